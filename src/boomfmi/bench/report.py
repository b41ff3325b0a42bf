"""The bench's plots (matplotlib, Agg) and its self-contained HTML page."""
from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np

from ..physics import friction_laws as fl

#: Display factors of the SI units in the tables (the units' names and display units as
#: :data:`boomfmi.units.UNITS` spells them): (factor, unit shown).
DISPLAY = {"m2": (1e6, "mm2"), "N/Pa": (1e5, "N/bar"), "m/s": (1e3, "mm/s")}


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path: Path) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    data = buf.getvalue()
    path.write_bytes(data)
    return data


def friction_plots(doc: dict, path_for) -> dict[str, bytes]:
    """``friction_velocity.png`` and ``friction_pressure.png`` at ``path_for(name)``: the measured
    friction (with the chosen law's A_eff and F_0) against velocity and against
    pressure, and every law's fit."""
    from .friction import LAWS, friction
    plt = _pyplot()
    fits, fit_d, hold_d = doc["_data"]
    chosen = fits[doc["chosen"]].params
    pngs = {}

    def measured(d):
        return fl.measured_friction(d.F, d.p, chosen["A_eff"], chosen["F_0"])

    # friction against velocity: one panel per law
    laws = [law for law in LAWS if law in fits]
    fig, axes = plt.subplots(1, len(laws), figsize=(5.2 * len(laws), 4.2), sharey=True, squeeze=False)
    p_all = np.concatenate([fit_d.p, hold_d.p])
    norm = plt.Normalize(float(p_all.min()) / 1e5, float(p_all.max()) / 1e5)
    pressures = sorted({round(float(np.median(r.p)) / 1e5, 1) for r in fit_d.runs + hold_d.runs})
    for ax, law in zip(axes[0], laws):
        for d, marker, label in ((fit_d, ".", "FIT"), (hold_d, "x", "HOLD")):
            step = max(1, len(d) // 6000)
            ax.scatter(1e3 * d.v[::step], measured(d)[::step], c=d.p[::step] / 1e5, cmap="viridis", norm=norm,
                       s=3, marker=marker, alpha=0.35, label=label)
        v_max = float(np.max(np.abs(np.concatenate([fit_d.v, hold_d.v]))))
        v = np.concatenate([np.linspace(-v_max, -1e-6, 200), np.linspace(1e-6, v_max, 200)])
        P = fits[law].params
        for p_bar in pressures:
            p = np.full_like(v, p_bar * 1e5)
            ax.plot(1e3 * v, friction(law, P, v, p, np.zeros_like(v)), color=plt.cm.viridis(norm(p_bar)), lw=1.6)
        ax.set_title(f"{law}: holdout RMSE {doc['laws'][law]['rmse_holdout_N']:.2f} N"
                     + ("  (chosen)" if law == doc["chosen"] else ""))
        ax.set_xlabel("velocity v [mm/s]")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("friction F - p A_eff - F_0 [N] (chosen law's A_eff, F_0)")
    axes[0][0].legend(loc="upper left", markerscale=4)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap="viridis"), ax=axes[0].tolist(), label="p [bar gauge]")
    pngs["friction_velocity.png"] = _save(fig, path_for("friction_velocity.png"))
    plt.close(fig)

    # friction against pressure: each stroke's settled sliding level, each direction
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    colors = {1: "tab:red", -1: "tab:blue"}
    speeds = {}
    for d, marker, label in ((fit_d, "o", "FIT"), (hold_d, "x", "HOLD")):
        f = measured(d)
        m = d.settled
        for direction in (1, -1):
            sel = m & (np.sign(d.v) == direction)
            ids = np.unique(d.stroke[sel])
            p_s = [np.median(d.p[sel & (d.stroke == k)]) for k in ids]
            f_s = [np.median(direction * f[sel & (d.stroke == k)]) for k in ids]
            ax.scatter(np.array(p_s) / 1e5, f_s, marker=marker, color=colors[direction], s=18, alpha=0.7,
                       label=f"{label}, {'v > 0' if direction > 0 else 'v < 0'}")
            if d is fit_d and np.any(sel):
                speeds[direction] = float(np.median(d.v[sel]))
    p_line = np.linspace(0.0, float(p_all.max()), 50)
    styles = {"eq9": ":", "stribeck": "--", "pressure": "-"}
    for law in laws:
        for direction, v0 in speeds.items():
            v = np.full_like(p_line, v0)
            level = direction * friction(law, fits[law].params, v, p_line, np.zeros_like(v))
            ax.plot(p_line / 1e5, level, styles.get(law, "-"), color=colors[direction], lw=1.4,
                    label=f"{law} at {1e3 * v0:+.1f} mm/s")
    ax.set_xlabel("chamber pressure p [bar gauge]")
    ax.set_ylabel("sliding friction magnitude [N]")
    ax.set_title("friction against pressure: each stroke's settled sliding level")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    pngs["friction_pressure.png"] = _save(fig, path_for("friction_pressure.png"))
    plt.close(fig)
    return pngs


def _fmt(value: float, unit: str) -> tuple[str, str]:
    factor, shown = DISPLAY.get(unit, (1.0, unit))
    return f"{value * factor:.4g}", shown


def _img(name: str, data: bytes) -> str:
    return (f'<figure><img alt="{html.escape(name)}" src="data:image/png;base64,'
            f'{base64.b64encode(data).decode()}"><figcaption>{html.escape(name)}</figcaption></figure>')


def friction_html(doc: dict, pngs: dict[str, bytes], path: Path) -> None:
    """``friction.html``: the files, every law's parameters with intervals and errors,
    the choice, the plots embedded."""
    e = html.escape
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>Friction bench</title><style>"
             "body{font-family:sans-serif;max-width:1200px;margin:2em auto}table{border-collapse:collapse;"
             "margin:.5em 0 1.5em}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}"
             "th{background:#eee}td:first-child{text-align:left}img{max-width:100%}.chosen{background:#e6f4e6}"
             "</style></head><body><h1>Friction bench</h1>"]
    parts.append(f"<p>FIT: {e(', '.join(doc['fit_files']))}<br>HOLD: {e(', '.join(doc['holdout_files']))}<br>"
                 f"nominal area {doc['area_nominal_m2'] * 1e6:.4g} mm<sup>2</sup>; samples: FIT "
                 f"{doc['samples']['fit']}, HOLD {doc['samples']['holdout']}; at rest below "
                 f"{doc['v_rest_m_s'] * 1e3:.2f} mm/s</p>")
    parts.append(f"<h2>Chosen law: {e(doc['chosen'])}</h2><p>{e(doc['choice']['rule'])}.</p><table><tr><th>simpler"
                 "</th><th>richer</th><th>holdout MSE gain [N<sup>2</sup>]</th><th>95 % interval</th>"
                 "<th>beats</th></tr>")
    for c in doc["choice"]["comparisons"]:
        parts.append(f"<tr><td>{e(c['simpler'])}</td><td>{e(c['richer'])}</td><td>{c['mse_gain_N2']:.3g}</td>"
                     f"<td>[{c['ci95'][0]:.3g}, {c['ci95'][1]:.3g}]</td><td>{'yes' if c['beats'] else 'no'}</td></tr>")
    parts.append("</table><h2>Laws</h2><table><tr><th>law</th><th>parameters</th><th>RMSE FIT [N]</th>"
                 "<th>RMSE HOLD [N]</th><th>formula</th></tr>")
    for law, L in doc["laws"].items():
        cls = " class='chosen'" if law == doc["chosen"] else ""
        parts.append(f"<tr{cls}><td>{e(law)}</td><td>{L['n_parameters']}</td><td>{L['rmse_fit_N']:.3f}</td>"
                     f"<td>{L['rmse_holdout_N']:.3f}</td><td style='text-align:left'>{e(L['formula'])}</td></tr>")
    parts.append("</table>")
    for law, L in doc["laws"].items():
        parts.append(f"<h3>{e(law)}</h3><table><tr><th>parameter</th><th>value</th><th>95 % interval</th>"
                     "<th>unit</th></tr>")
        for k, value in L["parameters"].items():
            unit = L["units"][k]
            v, shown = _fmt(value, unit)
            lo, _ = _fmt(L["intervals"][k][0], unit)
            hi, _ = _fmt(L["intervals"][k][1], unit)
            parts.append(f"<tr><td>{e(k)}</td><td>{v}</td><td>[{lo}, {hi}]</td><td>{e(shown)}</td></tr>")
        parts.append("</table>")
        if L.get("note"):
            parts.append(f"<p>{e(L['note'])}</p>")
    parts.append(f"<p>Intervals: {e(doc['interval_method'])}. Identifiability: {e(doc['identifiability'])}.</p>")
    for w in doc["warnings"]:
        parts.append(f"<p><b>warning:</b> {e(w)}</p>")
    parts += [_img(name, data) for name, data in pngs.items()]
    parts.append("</body></html>")
    path.write_text("\n".join(parts), encoding="utf-8")


def leak_plot(doc: dict, curves: list, path: Path) -> bytes:
    """``leak.png``: each run's pressure and every law's fit, and the chosen law's residual."""
    plt = _pyplot()
    n = len(curves)
    fig, axes = plt.subplots(2, n, figsize=(5 * n, 6.5), squeeze=False, sharex="col",
                             gridspec_kw={"height_ratios": [3, 1.3]})
    for j, (run, c) in enumerate(zip(doc["runs"], curves)):
        ax, axr = axes[0][j], axes[1][j]
        t, p, P_atm = c["t"], c["p"], doc["P_atm_Pa"]
        ax.plot(t, (p - P_atm) / 1e5, ".", ms=2, color="0.5", label="measured")
        for law, p_fit in c["fits"].items():
            ax.plot(t, (p_fit - P_atm) / 1e5, lw=1.3, label=law + (" (chosen)" if law == run["chosen"] else ""))
        axr.plot(t, (p - c["fits"][run["chosen"]]) / 1e2, ".", ms=2)
        ax.set_title(run["file"], fontsize=9)
        ax.set_ylabel("p [bar gauge]")
        axr.set_ylabel(f"{run['chosen']} residual [mbar]")
        axr.set_xlabel("time since the chamber was closed [s]")
        ax.grid(alpha=0.3)
        axr.grid(alpha=0.3)
        ax.legend(fontsize=7)
    data = _save(fig, path)
    plt.close(fig)
    return data


__all__ = ["DISPLAY", "friction_plots", "friction_html", "leak_plot"]
