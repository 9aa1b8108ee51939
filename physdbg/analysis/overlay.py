"""The diff overlay: two runs in one Rerun recording, side by side, opened at the divergence.

Run A is drawn under ``/a``, run B under ``/b`` (each exactly as ``replay`` draws it).
The blueprint puts the two 3D views side by side, overlays both runs' energy and
contacts-per-step plots, and lists the divergence with both event logs. The diverging
spheres are ringed in magenta in both views from the diverging step on, a log line says
what happened, and the time panel opens on the steps around it.
"""

from __future__ import annotations

import uuid

import numpy as np

CONTEXT_STEPS = 20  # steps shown either side of the divergence when the file opens


def write_overlay(a, b, report, rrd_path: str | None, spawn: bool = False) -> str | None:
    """Write (and/or stream) the overlay of recordings a and b; returns the .rrd path."""
    import rerun as rr

    from ..record import open_recording
    from ..record.rerun_sink import APPLICATION_ID, RerunSink, viewer_binary

    stream = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4().hex)
    stream.set_log_time_enabled(False)
    sinks = []
    if rrd_path is not None:
        sinks.append(rr.FileSink(str(rrd_path)))
    if spawn:
        rr.spawn(connect=False, hide_welcome_screen=True, executable_path=viewer_binary(), recording=stream)
        sinks.append(rr.GrpcSink())
    stream.set_sinks(*sinks)
    div = report.divergence
    with open_recording(a) as ra, open_recording(b) as rb:
        stream.send_blueprint(_blueprint(ra, rb, report), make_active=True, make_default=True)
        stream.send_recording_name(f"diff {ra.header.name} vs {rb.header.name}")
        for root, rec, step in (("a", ra, div.step if div else None), ("b", rb, div.step_b if div else None)):
            sink = RerunSink(rec.header, stream=stream, root=root, detail="contacts" if rec.detail != "state" else "state")
            watched = [p["particle"] for p in div.state.particles] if div else []
            for events in rec.iter_step_events(detail=sink.detail):
                for event in events:
                    sink.on_event(event)
                end = events[-1]
                if step is not None and end.step + 1 >= step and watched:
                    stream.set_time("step", sequence=end.step + 1)
                    stream.set_time("sim_time", duration=end.time)
                    stream.log(f"{root}/world/diverging", rr.Points3D(
                        np.asarray(end.positions[watched], dtype=np.float32),
                        radii=(1.25 * rec.header.radius[watched]).astype(np.float32),
                        colors=[[255, 0, 200, 110]], labels=[f"{p}" for p in watched]))
            sink.close()
        if div is not None:
            stream.set_time("step", sequence=div.step)
            stream.set_time("sim_time", duration=div.time)
            stream.log("divergence", rr.TextLog(f"step {div.step}: {report.headline}", level="WARN"))
            for cause in report.causes:
                stream.log("divergence", rr.TextLog(f"[{cause.kind}] {cause.text}", level="INFO"))
    stream.flush()
    stream.disconnect()
    return str(rrd_path) if rrd_path else None


def _blueprint(ra, rb, report):
    import rerun.blueprint as rrb

    from ..record.rerun_sink import BVH_LEVELS_SHOWN

    div = report.divergence
    hidden = {f"/{root}/world/bvh/level_{level}": rrb.EntityBehavior(visible=False)
              for root in "ab" for level in range(BVH_LEVELS_SHOWN, 64)}
    panel = {}
    if div is not None:
        from rerun.encodings import AbsoluteTimeRange

        panel = {"time_selection": AbsoluteTimeRange(max(div.step - CONTEXT_STEPS, 0), div.step + CONTEXT_STEPS)}
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(
                rrb.Spatial3DView(origin="/a/world", name=f"A: {ra.path.name}", overrides=hidden),
                rrb.Spatial3DView(origin="/b/world", name=f"B: {rb.path.name}", overrides=hidden),
            ),
            rrb.Horizontal(
                rrb.TimeSeriesView(origin="/", contents=["/a/stats/energy/total", "/b/stats/energy/total"],
                                   name="total energy (J), A and B"),
                rrb.TimeSeriesView(origin="/", contents=["/a/stats/contacts", "/b/stats/contacts"],
                                   name="contacts per step, A and B"),
                rrb.TextLogView(origin="/", contents=["/divergence", "/a/log", "/b/log"], name="divergence and events"),
            ),
            row_shares=[3, 2],
        ),
        rrb.TimePanel(timeline="step", play_state="paused", **panel),
        collapse_panels=True,
    )
