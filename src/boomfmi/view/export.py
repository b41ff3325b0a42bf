"""The virtual view rendered to a video file, without a browser: ``boomfmi view --replay
RUN.csv --export out.mp4`` (or ``.gif``), for reports.

The same frames as the page (``frames.Run.frame``), the same elements: the linkage
in 3D (base, boom with its bucket, cylinder body and rod) for the machine, the model as
a translucent ghost, the estimated force as an arrow whose head is at the bucket (the
rig's true force beside it, grey), and the plots of p_a, p_b, x and the force over the
last 10 s.  Drawn by matplotlib; MP4 through the ffmpeg that imageio-ffmpeg ships,
GIF through Pillow.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .frames import Run, load_run, scene

MACHINE, GHOST, FORCE, TRUTH, STEEL, BASE = "#f0a030", "#5ab0ff", "#ff4d5e", "#9aa3b5", "#b8c0cc", "#59606c"
FORCE_SCALE = 0.15 / 500          # m of arrow per N, as on the page
WINDOW = 10.0


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
    """The figure and its artists; :meth:`show` poses them for one frame."""

    def __init__(self, run: Run, width: int, height: int):
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        self.run, self.g = run, scene(run.geom, run.L)
        self.fig = plt.figure(figsize=(width / 100, height / 100), dpi=100, facecolor="#14171c")
        grid = self.fig.add_gridspec(4, 2, width_ratios=(3, 2), left=0.01, right=0.98, top=0.95, bottom=0.06,
                                     hspace=0.45, wspace=0.12)
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
        self.text = self.fig.text(0.015, 0.93, "", color="#d9dee7", family="monospace", fontsize=9, va="top")
        self.fig.text(0.015, 0.975, f"boomfmi virtual view: {run.path.name}   machine (orange), model ghost "
                      f"(blue), f_est (red), f_ext (grey)", color="#8a93a3", fontsize=9)
        self.plots = []
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

    def _plot(self, cell, title: str, series) -> dict:
        ax = self.fig.add_subplot(cell, facecolor="#1c2027")
        ax.set_title(title, color="#d9dee7", fontsize=9, pad=3)
        ax.tick_params(colors="#8a93a3", labelsize=7)
        for s in ax.spines.values():
            s.set_color("#3a414d")
        ax.grid(color="#2a3039", lw=0.6)
        lines = [(get, ax.plot([], [], color=c, ls=ls, lw=1.3)[0]) for get, c, ls in series]
        return {"ax": ax, "lines": lines, "t": [], "y": [[] for _ in lines]}

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

    def show(self, t: float) -> list:
        f = self.run.frame(t)
        self._pose(self.machine, f["machine"])
        self._pose(self.ghost, f["model"])
        T = f["machine"]["T"]
        angle = math.atan2(T[1], T[0]) if T else 0.0
        self._arrow(self.f_est, self.f_est_head, f["f_est"], T, angle)
        self._arrow(self.f_ext, None, f["f_ext"], T, angle)
        deg = lambda p: f"{math.degrees(p['alpha']):6.2f}" if p and p["alpha"] is not None else "     -"
        num = lambda v, d=0: "-" if v is None else f"{v:.{d}f}"
        self.text.set_text(f"t      {f['t']:.3f} s\nalpha  {deg(f['machine'])} deg machine   {deg(f['model'])} deg model\n"
                           f"f_est  {num(f['f_est'])} N   f_ext {num(f['f_ext'])} N   f_reflect {num(f['f_reflect'], 2)} N")
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
                pad = 0.08 * (hi - lo) + 1e-6 * max(1.0, abs(hi))
                ax.set_ylim(lo - pad, hi + pad)
        return []


def _bar(p):
    return None if p is None else p / 1e5


def export(replay, out, fps: float = 25.0, start: float | None = None, stop: float | None = None,
           size: str = "1280x720") -> tuple[Path, int]:
    """Render the run file ``replay`` to ``out`` (.mp4 or .gif) at ``fps`` frames per
    second of the run's time, from ``start`` to ``stop`` [s] (default: all of it);
    return the path and the number of frames."""
    if not 1 <= fps <= 120:
        raise ValueError(f"--fps {fps:g}: from 1 to 120 frames per second")
    out = Path(out)
    writer = _writer(out, fps)
    width, height = _size(size)
    run = load_run(replay)
    if run.kind != "boom":
        raise ValueError(f"--export renders the boom's runs; {replay} is an excavator's: replay it on the page "
                         f"(boomfmi view --replay {replay})")
    t0 = run.t[0] if start is None else max(float(start), run.t[0])
    t1 = run.t[-1] if stop is None else min(float(stop), run.t[-1])
    if not t1 > t0:
        raise ValueError(f"nothing to render between {t0:g} and {t1:g} s (the run spans "
                         f"{run.t[0]:g} to {run.t[-1]:g} s)")
    times = np.arange(t0, t1 + 1e-9, 1.0 / fps)
    drawing = Drawing(run, width, height)
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
