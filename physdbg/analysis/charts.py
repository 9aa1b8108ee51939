"""Charts of benchmark results (matplotlib, the optional extra ``physdbg[charts]``).

Imported only when a chart is drawn; without matplotlib, ``ChartsMissing`` says how to
install it (``--no-chart`` skips the chart).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..engine import motion, toi
from ..errors import ChartsMissing
from .accuracy import PROBLEMS, Run, pareto

ERROR_FLOOR = 1e-17  # an error of exactly 0 is drawn here (a log axis has no 0)
# a marker per integrator and a colour per detection, in the engine's order of them (a
# method added to the engine gets the next one: nothing here names a method)
_MARKER_CYCLE = ("o", "s", "^", "D", "v", "P", "X", "*")
_COLOR_CYCLE = ("#1f77b4", "#ff7f0e", "#d62728", "#2ca02c", "#9467bd", "#8c564b")


def marker_of(integrator: str) -> str:
    """The chart marker of an integrator (by its place in motion.INTEGRATOR_NAMES)."""
    return _MARKER_CYCLE[motion.INTEGRATOR_NAMES.index(integrator) % len(_MARKER_CYCLE)]


def color_of(detection: str) -> str:
    """The chart colour of a detection method (by its place in toi.DETECTION_NAMES)."""
    return _COLOR_CYCLE[toi.DETECTION_NAMES.index(detection) % len(_COLOR_CYCLE)]





def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise ChartsMissing("the chart needs matplotlib: pip install 'physdbg[charts]' "
                            "(or pass --no-chart for the CSV and the table alone)") from None
    matplotlib.use("Agg")  # files only, never a window
    import matplotlib.pyplot as plt

    return plt


def accuracy_chart(runs: list[Run], paths: list[Path], title: str) -> None:
    """Error against cost, log–log, one panel per problem: marker shape = integrator, colour
    = detection, hollow = index ordering; runs that blew up as a black x at the top of
    their panel; each panel's Pareto front as a line. Written to every path (.png, .svg)."""
    plt = _pyplot()
    from matplotlib import ticker

    names = [name for name in PROBLEMS if any(r.problem == name for r in runs)]
    columns = min(4, len(names))
    rows = math.ceil(len(names) / columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.6 * rows), squeeze=False)
    for ax, name in zip(axes.flat, names, strict=False):
        mine = [r for r in runs if r.problem == name]
        finite = [r.error for r in mine if math.isfinite(r.error)]
        top = max([max(finite) * 10 if finite else 1.0, ERROR_FLOOR * 100])
        for run in mine:
            error = run.error if math.isfinite(run.error) else top
            if not math.isfinite(run.error):
                ax.scatter(run.ms_per_second, error, marker="x", color="black", s=30, zorder=3)
                continue
            hollow = run.ordering == "index"
            color = color_of(run.detection)
            ax.scatter(run.ms_per_second, max(error, ERROR_FLOOR), marker=marker_of(run.integrator), s=28,
                       facecolors="none" if hollow else color, edgecolors=color, linewidths=1.0, alpha=0.85,
                       zorder=2)
        front = [r for r in pareto(mine) if math.isfinite(r.error)]
        if front:
            ax.step([r.ms_per_second for r in front], [max(r.error, ERROR_FLOOR) for r in front], where="post",
                    color="#444444", linewidth=1.0, zorder=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda value, _: f"{value:g}"))
        ax.xaxis.set_minor_formatter(ticker.NullFormatter())
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("wall ms per simulated s", fontsize=8)
        ax.set_ylabel(f"error ({PROBLEMS[name].unit})", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="major", alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    handles = [plt.Line2D([], [], linestyle="", marker=marker_of(name), color="#555555", label=name)
               for name in motion.INTEGRATOR_NAMES]
    handles += [plt.Line2D([], [], linestyle="", marker="o", color=color_of(name), label=name)
                for name in toi.DETECTION_NAMES]
    handles += [plt.Line2D([], [], linestyle="", marker="o", markerfacecolor="none", color="#555555",
                           label="index ordering"),
                plt.Line2D([], [], linestyle="", marker="x", color="black", label="blew up"),
                plt.Line2D([], [], color="#444444", label="Pareto front")]
    _finish(plt, fig, handles, title, paths, bottom=0.05, dpi=110)


def accuracy_rrd(runs: list[Run], path: Path) -> None:
    """The same chart for the Rerun viewer: per problem a 2D view of log10(cost) against
    log10(error), each run a point labelled with its method and dt, the Pareto front a line."""
    import rerun as rr
    import rerun.blueprint as rrb

    rec = rr.RecordingStream("physdbg-accuracy")
    rec.set_sinks(rr.FileSink(str(path)))
    names = [name for name in PROBLEMS if any(r.problem == name for r in runs)]
    rec.send_blueprint(rrb.Blueprint(rrb.Grid(*[rrb.Spatial2DView(origin=f"/accuracy/{name}", name=name)
                                                for name in names])), make_active=True, make_default=True)
    for name in names:
        mine = [r for r in runs if r.problem == name]
        top = max([r.error for r in mine if math.isfinite(r.error)] + [ERROR_FLOOR]) * 10
        points = [[math.log10(r.ms_per_second), -math.log10(max(r.error if math.isfinite(r.error) else top,
                                                                   ERROR_FLOOR))] for r in mine]
        colors = [[int(color_of(r.detection)[i:i + 2], 16) for i in (1, 3, 5)] for r in mine]
        labels = [f"{r.method} 1/{round(1 / r.dt)}: {r.error:.2g} {r.unit}" + (f" ({r.failure})" if r.failure else "")
                  for r in mine]
        rec.log(f"accuracy/{name}/runs", rr.Points2D(points, colors=colors, labels=labels, radii=[-4.0]), static=True)
        front = [r for r in pareto(mine) if math.isfinite(r.error)]
        if len(front) > 1:
            rec.log(f"accuracy/{name}/pareto", rr.LineStrips2D(
                [[[math.log10(r.ms_per_second), -math.log10(max(r.error, ERROR_FLOOR))] for r in front]]),
                static=True)
        rec.log(f"accuracy/{name}/axes", rr.TextDocument(
            f"x: log10(wall ms per simulated s); y: -log10(error in {PROBLEMS[name].unit}) (up = more accurate)"),
            static=True)
    rec.flush()
    rec.disconnect()


OUTCOME_COLORS = {"pass": "#2ca02c", "blew up": "#000000", "tunnelled": "#d62728", "budget hit": "#9467bd",
                  "overlap left": "#ff7f0e", "energy changed": "#1f77b4", "sank": "#8c564b"}


def stability_chart(cells, which: str, paths: list[Path], title: str) -> None:
    """A heatmap per integrator × detection (rows × columns) of one map's outcomes. The
    impact map is drawn on log dt × log speed with the boundaries the geometry predicts
    (analysis.stability): v·dt = REACH/(7/8) for discrete detection, 2k·REACH for sampled."""
    plt = _pyplot()
    from matplotlib.colors import ListedColormap

    from .stability import OUTCOMES, PHASES, REACH

    mine = [c for c in cells if c.map == which]
    integrators = list(dict.fromkeys(c.integrator for c in mine))
    detections = list(dict.fromkeys(c.detection for c in mine))
    xs, ys = sorted({c.x for c in mine}), sorted({c.y for c in mine})
    cmap = ListedColormap([OUTCOME_COLORS[o] for o in OUTCOMES])
    fig, axes = plt.subplots(len(integrators), len(detections), figsize=(3.4 * len(detections),
                                                                      2.7 * len(integrators)), squeeze=False)
    for row, integrator in enumerate(integrators):
        for col, detection in enumerate(detections):
            ax = axes[row][col]
            grid = np.full((len(ys), len(xs)), np.nan)
            for c in mine:
                if c.integrator == integrator and c.detection == detection:
                    grid[ys.index(c.y), xs.index(c.x)] = OUTCOMES.index(c.outcome)
            ax.pcolormesh(_edges(xs, which == "impact"), _edges(ys, which == "impact"), grid, cmap=cmap,
                          vmin=-0.5, vmax=len(OUTCOMES) - 0.5, shading="flat")
            if which == "impact":
                ax.set_xscale("log")
                ax.set_yscale("log")
                dts = np.array([xs[0] / 1.5, xs[-1] * 1.5])
                if detection == "discrete":
                    ax.plot(dts, REACH / (1 - PHASES[0]) / dts, color="white", linewidth=1.2, linestyle="--")
                if detection == "sampled":
                    ax.plot(dts, 2 * 4 * REACH / dts, color="white", linewidth=1.2, linestyle="--")
                ax.set_xlim(dts[0], dts[1])
                ax.set_ylim(ys[0] / 1.5, ys[-1] * 1.5)
            else:
                ax.set_yscale("log", base=2)
            ax.set_title(f"{integrator} / {detection}", fontsize=9)
            ax.tick_params(labelsize=7)
            if row == len(integrators) - 1:
                ax.set_xlabel("dt (s)" if which == "impact" else "restitution", fontsize=8)
            if col == 0:
                ax.set_ylabel("impact speed (m/s)" if which == "impact" else "spheres in the stack", fontsize=8)
    handles = [plt.Line2D([], [], linestyle="", marker="s", markersize=9, color=OUTCOME_COLORS[o], label=o)
               for o in OUTCOMES if any(c.outcome == o for c in mine)]
    if which == "impact":
        handles += [plt.Line2D([], [], color="#555555", linestyle="--",
                               label="predicted: v·dt = (t/2 + r)/(7/8) discrete, 8 (t/2 + r) sampled (k = 4)")]
    _finish(plt, fig, handles, title, paths, bottom=0.04, dpi=100)


ENGINE_MARKERS = {"physdbg": "D", "pybullet": "o", "mujoco": "s"}
ENGINE_ERRORS = (("largest_overlap", "largest overlap (m)"), ("energy_error", "energy error (of E at start)"),
                 ("contact_time_error", "first contact, time error (s)"), ("tunnelled", "bodies tunnelled"))


def engines_chart(runs, paths: list[Path], title: str) -> None:
    """Cost against error across engines: one panel per error measure, ms/step (log) on x,
    the error (log; 0 drawn on the floor line) on y; marker shape = engine, colour = scene,
    each point labelled with its setting. Written to every path (.png, .svg)."""
    plt = _pyplot()
    from matplotlib import ticker

    scenes = list(dict.fromkeys(r.scene for r in runs))
    palette = plt.get_cmap("tab10")
    colors = {scene: palette(k % 10) for k, scene in enumerate(scenes)}
    fig, axes = plt.subplots(2, 2, figsize=(11.0, 8.5), squeeze=False)
    for ax, (field, label) in zip(axes.flat, ENGINE_ERRORS, strict=True):
        measured = [r for r in runs if not r.failure and getattr(r, field) is not None and r.ms_per_step]
        values = [getattr(r, field) for r in measured if getattr(r, field) > 0]
        floor = min(values) / 10 if values else 1e-3
        for run in measured:
            value = getattr(run, field)
            ax.scatter(run.ms_per_step, value if value > 0 else floor, marker=ENGINE_MARKERS.get(run.engine, "o"),
                       s=30, color=colors[run.scene], edgecolors="black" if run.engine == "physdbg" else "none",
                       linewidths=0.6, alpha=0.85, zorder=2)
        ax.axhline(floor, color="#999999", linewidth=0.8, linestyle=":", zorder=1)
        ax.text(0.01, floor, " 0 (exact)", transform=ax.get_yaxis_transform(), fontsize=7, color="#777777",
                va="bottom")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda value, _: f"{value:g}"))
        ax.set_title(label, fontsize=10)
        ax.set_xlabel("ms per step (log)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="major", alpha=0.3)
    handles = [plt.Line2D([], [], linestyle="", marker=m, color="#555555", label=name)
               for name, m in ENGINE_MARKERS.items()]
    handles += [plt.Line2D([], [], linestyle="", marker="o", color=c, label=name) for name, c in colors.items()]
    _finish(plt, fig, handles, title, paths, bottom=0.06, dpi=110)


def _finish(plt, fig, handles, title: str, paths: list[Path], bottom: float, dpi: int) -> None:
    """Legend below the panels, title above, written to every path, closed."""
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, bottom, 1, 0.96))
    for path in paths:  # no creation date in an SVG's metadata: the same run writes the same file
        fig.savefig(path, dpi=dpi, metadata={"Date": None} if str(path).endswith(".svg") else None)
    plt.close(fig)


def _edges(centres: list[float], log: bool) -> np.ndarray:
    """Cell edges around sorted centres (geometric midpoints on a log axis)."""
    c = np.log(centres) if log else np.asarray(centres, dtype=float)
    if len(c) == 1:
        edges = np.array([c[0] - 0.5, c[0] + 0.5])
    else:
        mid = (c[1:] + c[:-1]) / 2
        edges = np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])
    return np.exp(edges) if log else edges
