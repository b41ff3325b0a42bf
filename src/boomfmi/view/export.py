"""The virtual view rendered to a video file, without a browser: ``boomfmi view --replay
RUN.csv --export out.mp4`` (or ``.gif``), for reports.

The same frames as the page (``frames.Run.frame``), the same elements; one
:class:`Drawing`, its machine's artists its mechanism's.  The boom (:class:`BoomDrawing`):
the linkage in 3D (base, boom with its bucket, cylinder body and rod) for the machine, the
model as a translucent ghost, the estimated force as an arrow whose head is at the bucket
(the rig's true force beside it, grey), and the plots of p_a, p_b, x and the force over
the last 10 s.  The excavator (:class:`LinkageDrawing`, a ``frames.Run`` of the
``LinkageMechanism``) is drawn in two orthographic projections, the side (x-z) and the top (x-y), from the points of the linkage's forward
kinematics its frames carry: the upper structure, boom, arm and bucket and the four
cylinders, the model's ghost, the tip forces as arrows whose heads are at the tip, and the
page's plots (joint angles, p_a and p_b per joint, the tip force).  Drawn by matplotlib;
MP4 through the ffmpeg that imageio-ffmpeg ships, GIF through Pillow.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..physics import linkage
from .frames import TIP_FORCE_SCALE, Run, heading, load_run

MACHINE, GHOST, FORCE, TRUTH, STEEL, BASE = "#f0a030", "#5ab0ff", "#ff4d5e", "#9aa3b5", "#b8c0cc", "#59606c"
FORCE_SCALE = 0.15 / 500          # m of arrow per N, as on the page
WINDOW = 10.0
#: the excavator's plot colours per joint, and of the tip force's axes, as on the page
JOINT_COLORS = {"swing": "#c792ea", "boom": "#f0a030", "arm": "#7fd17f", "bucket": "#5ad8e6"}
AXIS_COLORS = ("#ff4d5e", "#7fd17f", "#5ab0ff")
TIP_ARROW_MIN = 0.5               # N: a smaller tip force is not drawn, as on the page


def _writer(path: Path, fps: float):
    from matplotlib import animation
    suffix = path.suffix.lower()
    if suffix == ".gif":
        return animation.PillowWriter(fps=fps)
    if suffix == ".mp4":
        import imageio_ffmpeg
        import matplotlib
        matplotlib.rcParams["animation.ffmpeg_path"] = imageio_ffmpeg.get_ffmpeg_exe()
        return animation.FFMpegWriter(fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p"])
    raise ValueError(f"--export {path}: the file must end in .mp4 or .gif")


def _size(size: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in size.lower().split("x"))
    except ValueError:
        raise ValueError(f"--size {size!r}: expected WIDTHxHEIGHT, e.g. 1280x720") from None
    if not (160 <= w <= 3840 and 120 <= h <= 2160):
        raise ValueError(f"--size {size!r}: from 160x120 to 3840x2160 pixels")
    return w - w % 2, h - h % 2             # H.264 wants even sides


class Drawing:
    """A run's drawing, for the machine of one joint or four: the figure, its grid (the
    machine on the left, four plots of the last WINDOW seconds on the right), the title
    and the read-out; :meth:`show` poses it for one frame, :meth:`_update_plots` appends a
    frame to the plots.  The machine's own artists are its mechanism's
    (:class:`BoomDrawing`, :class:`LinkageDrawing`); :meth:`of` makes the run's."""

    def __init__(self, run, width: int, height: int, legend: str, left: float = 0.01):
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        self.run = run
        self.fig = plt.figure(figsize=(width / 100, height / 100), dpi=100, facecolor="#14171c")
        self.grid = self.fig.add_gridspec(4, 2, width_ratios=(3, 2), left=left, right=0.98, top=0.95, bottom=0.06,
                                          hspace=0.45, wspace=0.12)
        self.text = self.fig.text(0.015, 0.93, "", color="#d9dee7", family="monospace", fontsize=9, va="top")
        self.fig.text(0.015, 0.975, f"boomfmi virtual view: {run.path.name}   {legend}", color="#8a93a3", fontsize=9)
        self.plots = []

    @staticmethod
    def of(run: Run, width: int, height: int) -> "Drawing":
        """The drawing of ``run``'s mechanism (``frames.Run.kind``)."""
        return {"boom": BoomDrawing, "excavator": LinkageDrawing}[run.kind](run, width, height)

    def show(self, t: float) -> list:
        f = self.run.frame(t)
        self._pose(self.machine, f["machine"])
        self._pose(self.ghost, f["model"])
        self._forces(f)
        self.text.set_text(self._readout(f))
        self._update_plots(f)
        return []

    def _axes(self, cell, title: str):
        """An axes of the figure in the page's style."""
        ax = self.fig.add_subplot(cell, facecolor="#1c2027")
        ax.set_title(title, color="#d9dee7", fontsize=9, pad=3)
        ax.tick_params(colors="#8a93a3", labelsize=7)
        for s in ax.spines.values():
            s.set_color("#3a414d")
        ax.grid(color="#2a3039", lw=0.6)
        return ax

    def _plot(self, cell, title: str, series) -> dict:
        ax = self._axes(cell, title)
        lines = [(get, ax.plot([], [], color=c, ls=ls, lw=1.3)[0]) for get, c, ls in series]
        return {"ax": ax, "lines": lines, "t": [], "y": [[] for _ in lines]}

    def _update_plots(self, f: dict) -> None:
        for p in self.plots:
            p["t"].append(f["t"])
            while p["t"] and p["t"][0] < f["t"] - WINDOW:
                p["t"].pop(0)
                for y in p["y"]:
                    y.pop(0)
            for (get, line), y in zip(p["lines"], p["y"]):
                v = get(f)
                y.append(np.nan if v is None else v)
                line.set_data(p["t"], y)
            ax = p["ax"]
            ax.set_xlim(max(self.run.t[0], f["t"] - WINDOW), max(f["t"], self.run.t[0] + 1.0))
            ys = np.array([v for y in p["y"] for v in y], float)
            ys = ys[np.isfinite(ys)]
            if ys.size:
                lo, hi = float(ys.min()), float(ys.max())
                pad = 0.08 * (hi - lo) if hi > lo else 0.05 * abs(hi) or 1.0
                ax.set_ylim(lo - pad, hi + pad)


class BoomDrawing(Drawing):
    """The boom's artists: the linkage in 3D, its ghost and the piston's forces."""

    def __init__(self, run: Run, width: int, height: int):
        super().__init__(run, width, height, "machine (orange), model ghost (blue), f_est (red), f_ext (grey)")
        self.g = run.scene()
        grid = self.grid
        ax = self.fig.add_subplot(grid[:, 0], projection="3d", facecolor="#1c2027")
        self.ax3 = ax
        g = self.g
        ax.view_init(elev=14, azim=-78)
        ax.set_xlim(-0.1, 0.6)
        ax.set_ylim(-0.25, 0.25)          # depth: the boom's plane is y = 0 here
        ax.set_zlim(-0.2, 0.5)
        ax.set_box_aspect((0.7, 0.5, 0.7))
        ax.set_axis_off()
        z0 = g["C"][1] - 0.12
        gx = np.linspace(-0.1, 0.6, 8)
        for v in gx:                                     # the ground's grid
            ax.plot([v, v], [-0.25, 0.25], [z0, z0], color="#2a3039", lw=0.6)
        for v in np.linspace(-0.25, 0.25, 6):
            ax.plot([-0.1, 0.6], [v, v], [z0, z0], color="#2a3039", lw=0.6)
        ax.plot([0, 0], [0, 0], [z0, 0], color=BASE, lw=9, solid_capstyle="butt")          # the post under O
        ax.plot([0, g["C"][0] + 0.04], [0, 0], [g["C"][1] - 0.03] * 2, color=BASE, lw=8)   # the sill under C
        for p in (g["O"], g["C"]):
            ax.plot([p[0]], [0], [p[1]], "o", color=STEEL, ms=6)
        self.machine = self._mechanism(MACHINE, 1.0)
        self.ghost = self._mechanism(GHOST, 0.35)
        self.f_est, = ax.plot([], [], [], color=FORCE, lw=3)
        self.f_est_head, = ax.plot([], [], [], "v", color=FORCE, ms=9)
        self.f_ext, = ax.plot([], [], [], color=TRUTH, lw=2, ls="--")
        series = [("p_a [bar gauge]", lambda f, k: _bar(f[k]["p_a"]) if f[k] else None),
                  ("p_b [bar gauge]", lambda f, k: _bar(f[k]["p_b"]) if f[k] else None),
                  ("x [mm]", lambda f, k: f[k]["x"] * 1e3 if f[k] and f[k]["x"] is not None else None)]
        for i, (title, get) in enumerate(series):
            self.plots.append(self._plot(grid[i, 1], title, [(lambda f, get=get: get(f, "machine"), MACHINE, "-"),
                                                             (lambda f, get=get: get(f, "model"), GHOST, "--")]))
        self.plots.append(self._plot(grid[3, 1], "force on the piston [N]",
                                     [(lambda f: f["f_est"], FORCE, "-"), (lambda f: f["f_ext"], TRUTH, "--")]))

    def _mechanism(self, color: str, alpha: float) -> dict:
        ax = self.ax3
        return {"boom": ax.plot([], [], [], color=color, lw=7, alpha=alpha, solid_capstyle="butt")[0],
                "bucket": ax.plot([], [], [], "s", color=color, ms=13, alpha=alpha)[0],
                "body": ax.plot([], [], [], color=color, lw=10, alpha=alpha, solid_capstyle="butt")[0],
                "rod": ax.plot([], [], [], color=STEEL if alpha == 1.0 else color, lw=4, alpha=alpha)[0]}

    def _pose(self, m: dict, f: dict | None) -> None:
        if f is None or f["R"] is None:
            for a in m.values():
                a.set_data_3d([], [], [])
            return
        g, R, T = self.g, f["R"], f["T"]
        m["boom"].set_data_3d([0.0, T[0]], [0.0, 0.0], [0.0, T[1]])
        m["bucket"].set_data_3d([T[0]], [0.0], [T[1] - 0.02])
        C = g["C"]
        l = math.hypot(R[0] - C[0], R[1] - C[1])
        ux, uy = (R[0] - C[0]) / l, (R[1] - C[1]) / l
        m["body"].set_data_3d([C[0], C[0] + ux * g["body_length"]], [0, 0], [C[1], C[1] + uy * g["body_length"]])
        r0 = l - g["rod_length"]
        m["rod"].set_data_3d([C[0] + ux * r0, R[0]], [0, 0], [C[1] + uy * r0, R[1]])

    def _arrow(self, line, head, force, T, angle) -> None:
        if force is None or T is None or abs(force) < 2:
            line.set_data_3d([], [], [])
            if head is not None:
                head.set_data_3d([], [], [])
            return
        s = math.copysign(1.0, force)
        dx, dy = s * math.sin(angle), -s * math.cos(angle)
        n = max(0.02, abs(force) * FORCE_SCALE)
        line.set_data_3d([T[0] - dx * n, T[0]], [0.03, 0.03], [T[1] - dy * n, T[1]])
        if head is not None:
            head.set_data_3d([T[0]], [0.03], [T[1]])
            head.set_marker("v" if dy < 0 else "^")

    def _forces(self, f: dict) -> None:
        T = f["machine"]["T"]
        angle = math.atan2(T[1], T[0]) if T else 0.0
        self._arrow(self.f_est, self.f_est_head, f["f_est"], T, angle)
        self._arrow(self.f_ext, None, f["f_ext"], T, angle)

    def _readout(self, f: dict) -> str:
        deg = lambda p: f"{math.degrees(p['alpha']):6.2f}" if p and p["alpha"] is not None else "     -"
        num = lambda v, d=0: "-" if v is None else f"{v:.{d}f}"
        return (f"t      {f['t']:.3f} s\nalpha  {deg(f['machine'])} deg machine   {deg(f['model'])} deg model\n"
                f"f_est  {num(f['f_est'])} N   f_ext {num(f['f_ext'])} N   f_reflect {num(f['f_reflect'], 2)} N")


#: the excavator's drawn segments: the upper structure (swing axis to boom pivot) and
#: the links, from the points of ``physics.linkage.forward_kinematics``
EXCAVATOR_LINKS = (("upper", "swing_axis", "boom_pivot", 6), ("boom", "boom_pivot", "arm_pivot", 7),
                   ("arm", "arm_pivot", "bucket_pivot", 6), ("bucket", "bucket_pivot", "tip", 8))
CYLINDER_BODY = 0.55              # the body's share of a cylinder's eye-to-eye length, as on the page
TIP_SIDE = 0.03                   # m: the arrows' heads beside the tip, across the machine's plane


class LinkageDrawing(Drawing):
    """The whole excavator's artists: two orthographic projections of the machine, the
    side (x-z, large) and the top (x-y), the model's ghost and the tip forces in both,
    and its plots."""

    def __init__(self, run: Run, width: int, height: int):
        super().__init__(run, width, height, "machine (orange), model ghost (blue), f_tip_est (red), "
                                             "f_tip (grey)", left=0.04)
        left = self.grid[:, 0].subgridspec(2, 2, height_ratios=(3, 2), hspace=0.18, wspace=0.08)
        self.views = []                          # (axes, the world axis drawn upwards: z side, y top)
        for cell, k, title, ylim in ((left[0, :], 2, "side (x-z) [m]", (-0.45, 0.75)),
                                     (left[1, 0], 1, "top (x-y) [m]", (-0.5, 0.5))):
            ax = self._axes(cell, title)
            ax.set_xlim(-0.2, 1.05)
            ax.set_ylim(*ylim)
            ax.set_aspect("equal", adjustable="box")
            self.views.append((ax, k))
        import matplotlib.patches as mpatches
        side, top = (ax for ax, _ in self.views)
        side.axhline(0.0, color=BASE, lw=1.5)                                         # the ground
        side.add_patch(mpatches.Rectangle((-0.15, 0.0), 0.30, 0.10, color=BASE))      # the undercarriage
        top.add_patch(mpatches.Rectangle((-0.15, -0.11), 0.30, 0.22, color=BASE))
        top.add_patch(mpatches.Circle((0.0, 0.0), 0.09, fc="none", ec=STEEL, lw=1.2))  # the upper structure's deck
        self.machine = self._mechanism(MACHINE, STEEL, 1.0)
        self.ghost = self._mechanism(GHOST, GHOST, 0.35)
        self.arrows = {"f_tip_est": self._arrows(FORCE), "f_tip": self._arrows(TRUTH)}
        box = left[1, 1].get_position(self.fig)
        self.text.set_position((box.x0 + 0.01, box.y1))
        joints = linkage.JOINTS
        deg = lambda v: None if v is None else math.degrees(v)

        def per_joint(q: str, conv) -> list:
            return [(lambda f, q=q, j=j, who=who: conv(f[who][q][j]) if f[who] else None, JOINT_COLORS[j], ls)
                    for who, ls in (("machine", "-"), ("model", "--")) for j in joints]
        self.plots.append(self._plot(self.grid[0, 1], "joint angles [deg]: machine, model dashed",
                                     per_joint("angle", deg)))
        self.plots.append(self._plot(self.grid[1, 1], "p_a [bar gauge] per joint: machine, model dashed",
                                     per_joint("p_a", _bar)))
        self.plots.append(self._plot(self.grid[2, 1], "p_b [bar gauge] per joint: machine, model dashed",
                                     per_joint("p_b", _bar)))
        self.plots.append(self._plot(self.grid[3, 1], "tip force [N] x, y, z: estimated, truth dashed, "
                                                      "interval dotted",
                                     [(lambda f, key=key, k=k: f.get(key)[k] if f.get(key) else None, AXIS_COLORS[k],
                                       ls) for k in range(3) for key, ls in (("f_tip_est", "-"), ("f_tip", "--"),
                                                                             ("f_tip_lo", ":"), ("f_tip_hi", ":"))]))
        for p, labels, step in (*((self.plots[i], joints, 1) for i in range(3)),     # the machine's / estimate's
                                (self.plots[3], "xyz", 4)):
            for (_, line), label in zip(p["lines"][::step], labels):
                line.set_label(label)
            p["ax"].legend(loc="upper left", fontsize=6, ncol=len(labels), frameon=False, labelcolor="#d9dee7",
                           handlelength=1.2, columnspacing=0.8)

    def _mechanism(self, color: str, steel: str, alpha: float) -> list[dict]:
        """Per view, the links' and the cylinders' lines (a cylinder: its rod along the
        whole eye-to-eye length, the body over CYLINDER_BODY of it, from the base)."""
        out = []
        for ax, _ in self.views:
            m = {name: ax.plot([], [], color=color, lw=lw, alpha=alpha, solid_capstyle="round")[0]
                 for name, _, _, lw in EXCAVATOR_LINKS}
            for j in linkage.JOINTS:
                m[f"rod_{j}"] = ax.plot([], [], color=steel, lw=1.6, alpha=alpha)[0]
                m[f"body_{j}"] = ax.plot([], [], color=color, lw=4, alpha=alpha, solid_capstyle="butt")[0]
            out.append(m)
        return out

    def _arrows(self, color: str) -> list:
        from matplotlib.patches import FancyArrowPatch
        out = []
        for ax, _ in self.views:
            a = FancyArrowPatch((0, 0), (0, 0), arrowstyle="-|>", mutation_scale=12, color=color, lw=2.2,
                                shrinkA=0, shrinkB=0, visible=False, zorder=5)
            ax.add_patch(a)
            out.append(a)
        return out

    def _pose(self, m: list[dict], posture: dict | None) -> None:
        pts = posture["points"] if posture else None
        for (_, k), lines in zip(self.views, m):
            if pts is None:
                for line in lines.values():
                    line.set_data([], [])
                continue
            for name, a, b, _ in EXCAVATOR_LINKS:
                lines[name].set_data([pts[a][0], pts[b][0]], [pts[a][k], pts[b][k]])
            for j in linkage.JOINTS:
                base, rod = np.asarray(pts[f"cyl_{j}_base"]), np.asarray(pts[f"cyl_{j}_rod"])
                end = base + CYLINDER_BODY * (rod - base)
                lines[f"rod_{j}"].set_data([base[0], rod[0]], [base[k], rod[k]])
                lines[f"body_{j}"].set_data([base[0], end[0]], [base[k], end[k]])

    def _arrow(self, arrows: list, force, tip, side) -> None:
        """The tip force as an arrow whose head is beside the tip (``side``), its length
        TIP_FORCE_SCALE per N (at least 5 cm), projected into each view."""
        mag = math.hypot(*force) if force is not None else 0.0
        if tip is None or not mag >= TIP_ARROW_MIN:
            for a in arrows:
                a.set_visible(False)
            return
        head = np.asarray(tip, float) + side
        tail = head - np.asarray(force, float) / mag * max(0.05, mag * TIP_FORCE_SCALE)
        for (_, k), a in zip(self.views, arrows):
            a.set_positions((tail[0], tail[k]), (head[0], head[k]))
            a.set_visible(True)

    def _forces(self, f: dict) -> None:
        pts = f["machine"]["points"]
        tip = pts["tip"] if pts else None
        yaw = heading(pts) if pts else 0.0
        across = TIP_SIDE * np.array([-math.sin(yaw), math.cos(yaw), 0.0])
        self._arrow(self.arrows["f_tip_est"], f["f_tip_est"], tip, across)
        self._arrow(self.arrows["f_tip"], f["f_tip"], tip, -across)

    def _readout(self, f: dict) -> str:
        deg = lambda p, j: "      -" if not p or p["angle"][j] is None else f"{math.degrees(p['angle'][j]):7.2f}"
        vec = lambda v: "   -" if v is None else " ".join(f"{c:6.1f}" for c in v)
        lines = [f"t       {f['t']:.3f} s", "        machine  model [deg]"]
        lines += [f"{j:<8}{deg(f['machine'], j)}  {deg(f['model'], j)}" for j in linkage.JOINTS]
        lines += [f"f_tip_est [N] {vec(f['f_tip_est'])}", f"f_tip     [N] {vec(f['f_tip'])}"]
        return "\n".join(lines)


def _bar(p):
    return None if p is None else p / 1e5


def export(replay, out, fps: float = 25.0, start: float | None = None, stop: float | None = None,
           size: str = "1280x720", history: float | None = None) -> tuple[Path, int]:
    """Render the run file ``replay`` (the boom's or the excavator's) to ``out`` (.mp4 or
    .gif) at ``fps`` frames per second of the run's time, from ``start`` to ``stop`` [s]
    (default: all of it); return the path and the number of frames.  The plots of the
    first frame show the ``history`` seconds before ``start`` (default the plots' WINDOW,
    as the page does; 0: none), sampled at ``fps``."""
    if not 1 <= fps <= 120:
        raise ValueError(f"--fps {fps:g}: from 1 to 120 frames per second")
    history = WINDOW if history is None else float(history)
    if not (math.isfinite(history) and history >= 0):
        raise ValueError(f"--history {history:g}: seconds before --start, a finite number >= 0")
    out = Path(out)
    writer = _writer(out, fps)
    width, height = _size(size)
    run = load_run(replay)
    t0 = run.t[0] if start is None else max(float(start), run.t[0])
    t1 = run.t[-1] if stop is None else min(float(stop), run.t[-1])
    if not t1 > t0:
        raise ValueError(f"nothing to render between {t0:g} and {t1:g} s (the run spans "
                         f"{run.t[0]:g} to {run.t[-1]:g} s)")
    times = np.arange(t0, t1 + 1e-9, 1.0 / fps)
    drawing = Drawing.of(run, width, height)
    for t in np.arange(max(t0 - min(history, WINDOW), run.t[0]), t0 - 0.5 / fps, 1.0 / fps):
        drawing._update_plots(run.frame(float(t)))   # the plots' past: drawn, not a frame of the video
    out.parent.mkdir(parents=True, exist_ok=True)
    import matplotlib.pyplot as plt
    try:
        with writer.saving(drawing.fig, str(out), dpi=100):
            for t in times:
                drawing.show(float(t))
                writer.grab_frame(facecolor=drawing.fig.get_facecolor())
    finally:
        plt.close(drawing.fig)
    return out, len(times)


__all__ = ["MACHINE", "GHOST", "FORCE", "TRUTH", "STEEL", "BASE", "FORCE_SCALE", "WINDOW", "JOINT_COLORS",
           "AXIS_COLORS", "TIP_ARROW_MIN", "Drawing", "BoomDrawing", "EXCAVATOR_LINKS", "CYLINDER_BODY", "TIP_SIDE",
           "LinkageDrawing", "export"]
