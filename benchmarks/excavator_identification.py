"""Identification per joint and tip force estimation of the whole excavator, on the
excavator virtual rig (effect-free): prints each joint's identified K_v, F_s, F_d and
the payload against the truth (digging cycle + excavator_excitation, payload 0.5 kg;
the excitation drawn from each of ``--seeds``, under each sensor variant of
``--sensors``: ``standard`` the rig's own (500 Pa and 0.2 mrad of noise, 12-bit ADCs),
``noisy`` twice its noise, ``fine`` a fifth of the angle's and two fifths of the
pressures' noise and no ADC), the worst error per parameter over the seeds of each
variant and over all, then the tip force estimate on each scenario of
``experiments.TIP_FORCE_SCENARIOS`` (the digging cycle's three, and the closed-loop dig
through soft and hard soil and the load cell's push mid-workspace), over the contact
samples only: the RMSE per axis as a share of the peak force magnitude (target 10 %),
the estimate's delay, the coverage of its interval (the share of contact samples with
the true force inside, target 95 %) and its median width per axis against the best
possible (``excavator_tip_force_bounds.py``'s sets with exact sensors, every
``--every``-th contact sample) and the fair bound (``fair_bounds``: the set consistent with
the very standard-sensor recording the estimator sees, within its own noise, computed
offline with the rig's true sliding and sticking; what an interval with 95 % coverage
needs at the least).  ``--tip-only`` skips the identification.

    .venv/bin/python benchmarks/excavator_identification.py [--seeds 0 1 2] [--sensors standard,noisy,fine]
        [--tip-only] [--every 5]
    .venv/bin/python benchmarks/excavator_identification.py --noise-seeds 0 1 2 3 4 5 6 7 8 9

``--noise-seeds``: the same recordings' commands under each of the rig's noise draws
(``seed`` of the rig's config, separate from the excitation's seed) and each sensor
variant; per parameter the largest error, the mean signed error (F_s's target: within
+-1 %, no systematic sign), the unflagged misses (beyond 5 % and not flagged "cannot
tell" by ``identify.outputs.cannot_tell``) and the 95 % intervals' coverage
(target 90 %).
"""
import argparse
import time

import numpy as np

from boomfmi import experiments as E
from boomfmi.identify.joints import identify_joints, true_values
from boomfmi.physics.force_estimation import estimate_tip_force, tip_force_figures
from boomfmi.rig.config import NOISE
from boomfmi.rig import run_excavator_offline

PAYLOAD = 0.5
SENSORS = {
    "standard": dict(NOISE),
    "noisy": dict(NOISE, p_sigma=2.0 * NOISE["p_sigma"], alpha_sigma=2.0 * NOISE["alpha_sigma"]),
    "fine": dict(NOISE, p_sigma=0.4 * NOISE["p_sigma"], alpha_sigma=0.25 * NOISE["alpha_sigma"], quantise=False),
}


def noise_summary(rows, truth, flagged_ok=True):
    """Per parameter over ``rows`` (``(params, cannot_tell)`` of each run): the largest
    error, the mean signed error, the unflagged misses (beyond 5 % and not flagged
    "cannot tell") and the share of 95 % intervals that hold the truth; every target met."""
    ok = True
    for k in truth:
        errs = np.array([100.0 * (p[k].value - truth[k]) / truth[k] for p, _ in rows])
        cover = np.mean([p[k].ci95[0] <= truth[k] <= p[k].ci95[1] for p, _ in rows])
        misses = sum(abs(e) > 5.0 and why[k] is None for e, (_, why) in zip(errs, rows))
        flagged = sum(why[k] is not None for _, why in rows)
        mean_ok = not k.startswith("F_s") or abs(errs.mean()) <= 1.0
        ok &= misses == 0 and cover >= 0.9 and mean_ok
        print(f"  {k:12s} worst {np.max(np.abs(errs)):6.2f} %  mean {errs.mean():+6.2f} %"
              f"{'' if mean_ok else ' (F_s: OVER +-1 %)':18s} unflagged misses {misses:2d}  "
              f"coverage {100 * cover:5.1f} %{'' if cover >= 0.9 else ' (UNDER 90 %)':13s} cannot tell {flagged}/{len(rows)}")
    return ok


def _worst_lines(worst, covered, runs):
    for k in worst:
        print(f"  {k:12s} {worst[k]:6.2f} %  {'within 5 %' if worst[k] < 5 else 'OVER 5 %':10s} "
              f"covered {covered[k]}/{runs}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="excitation seeds")
    ap.add_argument("--noise-seeds", type=int, nargs="+", default=None,
                    help="the rig's noise seeds (its sensor noise draw), each with the same commands: "
                         "with it, the noise part runs (excitation seed: the first of --seeds) and the "
                         "excitation part is skipped; e.g. --noise-seeds 0 1 2 3 4 5 6 7 8 9")
    ap.add_argument("--sensors", default=",".join(SENSORS), help=f"sensor variants, of {', '.join(SENSORS)}")
    ap.add_argument("--tip-only", action="store_true", help="the tip force's figures only")
    ap.add_argument("--every", type=int, default=5, help="every n-th contact sample for the best possible width")
    ap.add_argument("--scenarios", default=",".join(E.TIP_FORCE_SCENARIOS), help="tip force scenarios")
    args = ap.parse_args(argv)
    if args.noise_seeds is not None:
        return 0 if noise_draws(args) else 1
    if not args.tip_only:
        identification(args)
    tip_force(args)


def noise_draws(args):
    """The same commands (the digging cycle and ``excavator_excitation`` of the first
    excitation seed) under each sensor variant and each of the rig's noise seeds: per
    parameter and variant, and over all, the summary of :func:`noise_summary`."""
    from boomfmi.identify.outputs import cannot_tell
    truth = true_values(payload=PAYLOAD)
    cmds = (E.digging_cycle(), E.excavator_excitation(seed=args.seeds[0]))
    every, ok = [], True
    for variant in args.sensors.split(","):
        rows = []
        for ns in args.noise_seeds:
            t0 = time.perf_counter()
            cfg = {"machine": "excavator", "payload": PAYLOAD, "noise": SENSORS[variant], "seed": ns}
            recs = [run_excavator_offline(cfg, c, c.duration) for c in cmds]
            result = identify_joints(recs)
            why = cannot_tell(result)
            rows.append((result.params, why))
            errs = "  ".join(f"{k} {100 * (e.value / truth[k] - 1):+.1f}%"
                             + ("" if e.ci95[0] <= truth[k] <= e.ci95[1] else "!") + ("?" if why[k] else "")
                             for k, e in result.params.items())
            print(f"{variant} sensors, noise seed {ns} ({time.perf_counter() - t0:.0f} s): {errs}", flush=True)
        print(f"{variant} sensors over {len(rows)} noise seeds (! interval misses the truth, ? cannot tell):")
        ok &= noise_summary(rows, truth)
        every += rows
    print(f"every variant, {len(every)} runs:")
    ok &= noise_summary(every, truth)
    print("targets (each parameter within 5 % or flagged, every F_s's mean error within +-1 %, "
          f"coverage >= 90 %): {'met' if ok else 'NOT met'}")
    return ok


def identification(args):
    truth = true_values(payload=PAYLOAD)
    all_worst, all_covered, runs = {}, {}, 0
    for variant in args.sensors.split(","):
        worst, covered = {}, {}
        for seed in args.seeds:
            t0 = time.perf_counter()
            cfg = {"machine": "excavator", "payload": PAYLOAD, "noise": SENSORS[variant]}
            recs = [run_excavator_offline(cfg, c, c.duration)
                    for c in (E.digging_cycle(), E.excavator_excitation(seed=seed))]
            t1 = time.perf_counter()
            result = identify_joints(recs)
            t2 = time.perf_counter()
            print(f"identification, {variant} sensors, excitation seed {seed} (rig {t1 - t0:.0f} s, fit {t2 - t1:.0f} s)")
            for k, e in result.params.items():
                err = 100.0 * (e.value - truth[k]) / truth[k]
                worst[k] = max(worst.get(k, 0.0), abs(err))
                covered[k] = covered.get(k, 0) + int(e.ci95[0] <= truth[k] <= e.ci95[1])
                print(f"  {k:12s} {e.value:10.4g} {e.unit:6s} true {truth[k]:10.4g}  error {err:+7.2f} %  "
                      f"95 % [{e.ci95[0]:.4g}, {e.ci95[1]:.4g}]")
            for w in result.warnings:
                print("  warning:", w)
        print(f"{variant} sensors: largest error over {len(args.seeds)} seed(s), and how many intervals cover the truth")
        _worst_lines(worst, covered, len(args.seeds))
        for k in worst:
            all_worst[k] = max(all_worst.get(k, 0.0), worst[k])
            all_covered[k] = all_covered.get(k, 0) + covered[k]
        runs += len(args.seeds)
    print(f"every variant: largest error over {runs} run(s), and how many intervals cover the truth")
    _worst_lines(all_worst, all_covered, runs)


def tip_force(args):
    """The tip force's figures per scenario, contact samples only (standard sensors)."""
    from excavator_tip_force_bounds import (CAUSAL_QUANTILE, best_bounds, causal_bounds_at_coverage, causal_fair_bounds,
                                            fair_bounds, median_width)
    print("tip force estimate (per-joint observers; the sliding joints' equations, the last estimate and the least "
          "squares' guess within the set of forces consistent with the sample; its interval), "
          "contact samples only, standard sensors")
    for name in args.scenarios.split(","):
        c, cmd = E.tip_force_scenario(name)
        d = run_excavator_offline({"machine": "excavator", "contact": c.config()}, cmd, cmd.duration)
        f, res, lo, hi = estimate_tip_force(d, bounds=True)
        ft = d[["f_tip_x", "f_tip_y", "f_tip_z"]].to_numpy()
        fig = tip_force_figures(d["t"].to_numpy(), ft, f, lo, hi)
        clipped = tip_force_figures(d["t"].to_numpy(), ft, np.clip(f, lo, hi))
        _, half, inside, none, _ = best_bounds(name, args.every)
        fair, fair_cov, fair_in, fair_n, corner, scale = fair_bounds(d, args.every)
        causal, causal_cov, causal_tol = causal_fair_bounds(d, args.every)
        lag = " / ".join(f"{1000 * v:.0f}" for v in fig["delay"])
        print(f"  {name}: {fig['contact_samples']} contact samples, peak magnitude {fig['peak']:.1f} N, delay "
              f"x / y / z {lag} ms, the true force inside the interval on all axes at "
              f"{100 * fig['coverage_all']:.1f} %; best possible (exact sensors, every {args.every}-th contact "
              f"sample): the truth in its set at {inside} of {len(half) + none}; fair bound (this recording, filtered "
              f"at {corner:g} Hz both ways, the rig's sliding, tolerance each joint's residual's {scale:g} quantile): the "
              f"truth in its set at {fair_in} of {fair_n}, per axis " + " / ".join(f"{100 * v:.1f}" for v in fair_cov)
              + " %; causal fair bound (the estimator's filters and states, each joint's tolerance its free-air "
              f"equation error's {CAUSAL_QUANTILE:g} quantile, " + " / ".join(f"{v:.1f}" for v in causal_tol)
              + " N): per axis " + " / ".join(f"{100 * v:.1f}" for v in causal_cov) + " %")
        free = np.linalg.norm(ft, axis=1) == 0.0
        false = np.sqrt(np.mean(f[free] ** 2, axis=0)) if free.any() else np.full(3, np.nan)
        whole = [np.sqrt(np.mean((f[:, k] - ft[:, k]) ** 2)) / np.max(np.abs(ft[:, k])) for k in range(3)]
        print(f"    free air ({int(free.sum())} samples, no contact): the estimate's false force RMS x / y / z "
              + " / ".join(f"{v:.2f}" for v in false) + " N; the whole run's RMSE over each axis' own peak "
              + " / ".join(f"{100 * v:.1f}" for v in whole) + " %")
        matched = causal_bounds_at_coverage(d, args.every, tol=causal_tol, at_tol=(causal, causal_cov))
        print("    the causal fair bound at >= 95 % coverage per axis (its free-air tolerances scaled until the truth "
              "lies in it at 95 % of the contact samples): median width x / y / z "
              + " / ".join(median_width(w) for w, _, _ in matched) + " at scales "
              + " / ".join(f"{s:g}" for _, _, s in matched) + " (coverage "
              + " / ".join(f"{100 * c:.1f}" for _, c, _ in matched) + " %); the estimator's median width over it: "
              + " / ".join(f"{fig['median_width'][k] / float(np.median(w)):.2f}" if np.isfinite(np.median(w))
                           and np.median(w) > 0 else "-" for k, (w, _, _) in enumerate(matched)))
        for k, ax in enumerate("xyz"):
            h = half[:, k]
            best = median_width(2.0 * h)
            rmse, share, cov, med = fig["rmse"][k], fig["rmse_share"][k], fig["coverage"][k], fig["median_width"][k]
            print(f"    {ax}: RMSE {rmse:6.2f} N = {100 * share:5.1f} % of the peak magnitude "
                  f"{'within 10 %' if share <= 0.1 else 'OVER 10 %':11s}; coverage {100 * cov:5.1f} % "
                  f"{'>= 95 %' if cov >= 0.95 else 'UNDER 95 %':10s}; median width {med:7.2f} N, fair bound "
                  f"{median_width(fair[:, k]):>8s}, causal fair bound {median_width(causal[:, k]):>8s}, best possible (exact sensors) {best:>8s}; the estimate clipped to "
                  f"its interval: {100 * clipped['rmse_share'][k]:5.1f} %")


if __name__ == "__main__":
    raise SystemExit(main())
