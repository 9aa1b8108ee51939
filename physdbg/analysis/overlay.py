"""The diff overlay: two runs in one Rerun recording, side by side, opened at the divergence.

Run A is drawn under ``/a`` with blue spheres, run B under ``/b`` with orange ones, each as
``replay`` draws it; the view titles and the plot legends say which is which. Both 3D
views have the same camera. The file opens paused on the diverging step: every row from
that step on also carries the ``diverged`` timeline, which the blueprint makes the active
one, and a paused viewer opens at the first time of its active timeline (pick ``step`` in
the time panel for the steps before). From the diverging step on, each diverging sphere
is ringed (a magenta wireframe that does not hide it) in both views, with an arrow to
where the other run has it and a wireframe of it there in the other run's colour. The
energy plot keeps a minimum height (MIN_ENERGY_RANGE), so a change of 1e-16 J from
rounding is not drawn as a full-height drop.
"""

from __future__ import annotations

import uuid
from itertools import zip_longest

import numpy as np

CONTEXT_STEPS = 20  # steps after the divergence selected in the time panel when the file opens
OPENING_TIMELINE = "diverged"  # the steps from the divergence on: where the file opens
COLOR_A = (60, 140, 255)  # run A's spheres and series: blue
COLOR_B = (255, 140, 30)  # run B's: orange
RING_COLOR = (255, 0, 200)  # the diverging spheres' rings: magenta
MIN_ENERGY_RANGE = 1e-6  # relative to the largest |energy|: the energy plot is at least this high


def write_overlay(a, b, report, rrd_path: str | None, spawn: bool = False, verify: bool = True) -> str | None:
    """Write (and/or stream) the overlay of recordings a and b; returns the .rrd path."""
    import rerun as rr

    from ..record import open_recording
    from ..record.rerun_sink import APPLICATION_ID, RerunSink, file_sink, viewer_binary

    stream = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4().hex)
    stream.set_log_time_enabled(False)
    sinks = []
    if rrd_path is not None:
        sinks.append(file_sink(rrd_path))
    if spawn:
        rr.spawn(connect=False, hide_welcome_screen=True, executable_path=viewer_binary(), recording=stream)
        sinks.append(rr.GrpcSink())
    stream.set_sinks(*sinks)
    div = report.divergence
    with open_recording(a, verify=verify) as ra, open_recording(b, verify=verify) as rb:
        stream.send_recording_name(f"diff {ra.header.name} vs {rb.header.name}")
        # opened at the divergence, or, where one run forks the other, where the fork starts
        at = report.fork.get("at") if report.fork else None
        runs = (("a", ra, COLOR_A, at or (div.step if div else None)),
                ("b", rb, COLOR_B, at or (div.step_b if div else None)))
        sinks = {root: RerunSink(rec.header, stream=stream, root=root, color=color,
                                 detail="contacts" if rec.detail != "state" else "state",
                                 opening=(OPENING_TIMELINE, step) if step is not None else None)
                 for root, rec, color, step in runs}
        for root, _, color, _ in runs:
            name = "A" if root == "a" else "B"
            stream.log(f"{root}/stats/energy/total", rr.SeriesLines(colors=[color], names=[f"{name}: total energy"]),
                       static=True)
            stream.log(f"{root}/stats/contacts", rr.SeriesLines(colors=[color], names=[f"{name}: contacts"]),
                       static=True)
        watched = [p["particle"] for p in div.state.particles] if div else []
        energy = [np.inf, -np.inf]
        ends = {}
        # in step with each other when both took the same steps, so each view can show
        # where the other run has a diverging sphere; one after the other otherwise
        streams = [ra.iter_step_events(detail=sinks["a"].detail), rb.iter_step_events(detail=sinks["b"].detail)]
        steps = zip_longest(*streams) if report.aligned_by == "step" else \
            [(events, None) for events in streams[0]] + [(None, events) for events in streams[1]]
        for pair in steps:
            for root, events in zip("ab", pair, strict=True):
                if events is None:
                    ends.pop(root, None)
                    continue
                for event in events:
                    sinks[root].on_event(event)
                ends[root] = events[-1]
                energy = [min(energy[0], events[-1].kinetic + events[-1].potential),
                          max(energy[1], events[-1].kinetic + events[-1].potential)]
            if div is not None and watched:
                _mark(stream, rr, runs, ends, watched)
        for sink in sinks.values():
            sink.close()
        if div is not None:
            stream.set_time("step", sequence=div.step)
            stream.set_time("sim_time", duration=div.time)
            stream.set_time(OPENING_TIMELINE, sequence=div.step)
            stream.log("divergence", rr.TextLog(f"step {div.step}: {report.headline}", level="WARN"))
            for cause in report.causes:
                stream.log("divergence", rr.TextLog(f"[{cause.kind}] {cause.text}", level="INFO"))
        stream.send_blueprint(_blueprint(ra, rb, report, energy), make_active=True, make_default=True)
    stream.flush()
    stream.disconnect()
    return str(rrd_path) if rrd_path else None


def _mark(stream, rr, runs, ends, watched) -> None:
    """Ring each diverging sphere in each run from the diverging step on, with an arrow to
    where the other run has it (and a wireframe of it there) when both are at this step."""
    for root, rec, color, step in runs:
        end = ends.get(root)
        if end is None or end.step < step:
            continue
        other = next((r for r in runs if r[0] != root), None)
        other_end = ends.get(other[0]) if other else None
        frame = end.step
        stream.set_time("step", sequence=frame)
        stream.set_time("sim_time", duration=end.time)
        stream.set_time(OPENING_TIMELINE, sequence=frame)
        here = np.asarray(end.positions[watched], dtype=np.float32)
        size = (1.35 * rec.header.radius[watched]).astype(np.float32)
        stream.log(f"{root}/world/diverging/rings", rr.Ellipsoids3D(
            centers=here, half_sizes=np.repeat(size[:, None], 3, axis=1), colors=[RING_COLOR],
            fill_mode="majorwireframe", line_radii=[-2.0], labels=[f"sphere {p}" for p in watched]))
        if other_end is not None and other_end.step == end.step:
            there = np.asarray(other_end.positions[watched], dtype=np.float32)
            stream.log(f"{root}/world/diverging/other_run", rr.Ellipsoids3D(
                centers=there, half_sizes=np.repeat(rec.header.radius[watched][:, None].astype(np.float32), 3, axis=1),
                colors=[other[2]], fill_mode="majorwireframe", line_radii=[-1.0]))
            stream.log(f"{root}/world/diverging/gap", rr.Arrows3D(origins=here, vectors=there - here,
                                                                   colors=[RING_COLOR], radii=[-2.0]))


def _blueprint(ra, rb, report, energy):
    import rerun.blueprint as rrb

    from ..record.rerun_sink import BVH_LEVELS_SHOWN, hidden_mesh_volumes, camera

    div = report.divergence
    hidden = {f"/{root}/world/bvh/level_{level}": rrb.EntityBehavior(visible=False)
              for root in "ab" for level in range(BVH_LEVELS_SHOWN, 64)}
    # a contact's ghost (a sphere where it touched) would hide the runs' own spheres here
    hidden.update({f"/{root}/world/contacts/ghosts": rrb.EntityBehavior(visible=False) for root in "ab"})
    # of each mesh's BVH, only the volume the run walked, its first levels (as a run's own file)
    for root, rec in (("a", ra), ("b", rb)):
        hidden.update(hidden_mesh_volumes(rec.header, f"/{root}"))
    panel = {"timeline": "step"}
    if div is not None:
        from rerun.encodings import AbsoluteTimeRange

        panel = {"timeline": OPENING_TIMELINE, "time_selection": AbsoluteTimeRange(div.step, div.step + CONTEXT_STEPS)}
    eye = camera(ra.header, distance=0.9)
    axis = {}
    low, high = energy
    if np.isfinite(low) and np.isfinite(high):
        least = MIN_ENERGY_RANGE * max(abs(low), abs(high), 1e-3)
        if high - low < least:
            middle = 0.5 * (low + high)
            axis = {"axis_y": rrb.ScalarAxis(range=(middle - least, middle + least))}
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(
                rrb.Spatial3DView(origin="/a/world", name=f"A (blue): {ra.path.name}", overrides=hidden,
                                  eye_controls=eye),
                rrb.Spatial3DView(origin="/b/world", name=f"B (orange): {rb.path.name}", overrides=hidden,
                                  eye_controls=eye),
            ),
            rrb.Horizontal(
                rrb.TimeSeriesView(origin="/", contents=["/a/stats/energy/total", "/b/stats/energy/total"],
                                   name="total energy (J), A and B", plot_legend=rrb.PlotLegend(visible=True),
                                   **axis),
                rrb.TimeSeriesView(origin="/", contents=["/a/stats/contacts", "/b/stats/contacts"],
                                   name="contacts per step, A and B", plot_legend=rrb.PlotLegend(visible=True)),
                rrb.TextLogView(origin="/", contents=["/divergence", "/a/log", "/b/log"], name="divergence and events"),
            ),
            row_shares=[3, 2],
        ),
        rrb.TimePanel(play_state="paused", **panel),
        collapse_panels=True,
    )
