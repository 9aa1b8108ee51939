"""The Rerun sink: an observer that draws a run for the Rerun viewer.

Why one module of this size: one observer writes one file, and its entities (listed
below) share the sink's state from step to step (what was drawn last, the blueprint's
opening step); what is drawn is computed in view.py and mesh_view.py.

The same sink serves a live recording (events from the engine) and a replay (events
read back from an MCAP file), so the two pictures are the same by construction.

Entities (timelines ``step`` = frame, steps completed, and ``sim_time`` in seconds):

    world/spheres            Points3D, one per particle, with radii (float32 copies)
    world/walls/<name>       LineStrips3D outline of each wall, so walls never hide spheres
    world/periodic/<face>    LineStrips3D outline (blue) of each face of a periodic axis
    world/meshes/<name>      Mesh3D of each mesh (translucent), and /edges its triangles' edges; a
                             kinematic mesh's Transform3D every step (it carries what is below)
    world/meshes/<name>/bvh/<volume>/level_<d>
                             the mesh's BVH (mesh_view.py), one entity per volume (aabb, obb,
                             sphere) and level: AABB levels 0..2 shown, the rest a click away
    world/mesh_search/{met,culled,triangles,queries}
                             every step's recorded search of the meshes' BVHs (events.MeshSearch;
                             detail contacts: the walks that led to a contact) by the spheres it
                             is about (mesh_view.searched_spheres: those that hit a mesh): the nodes
                             met and culled (each drawn as the volume it was walked with: a box
                             for an AABB or OBB, {met,culled}_spheres for a sphere), the triangles
                             reached and the boxes the engine asked with; world/mesh_search/all
                             the same for every sphere (hidden)
    search/triangles         the same search as a tree (GraphNodes, GraphEdges): the seed's
                             "search tree", a node per visit, for those spheres
    world/bvh/level_<d>      Boxes3D wireframes, one entity per BVH level (toggle levels;
                             the blueprint shows the first BVH_LEVELS_SHOWN)
    world/paths              LineStrips3D: each particle's path through the step,
                             through the centres where its contacts happened
    world/contacts/ghosts    Points3D: where each sphere was at each contact (the first
                             view.DRAWN_CONTACTS_PER_STEP of a step; the log says when more)
    world/contacts/normals   Arrows3D: contact normals (length = the sphere's radius)
    world/contacts/impulses  Arrows3D: velocity change of sphere a, × IMPULSE_ARROW_SECONDS
    world/findings           Points3D: a red marker where the audit found a problem
    stats/energy/*, stats/momentum/*, stats/contacts, stats/rapid, stats/released, stats/asleep (with sleeping on)
                             Scalars, sent in columns
    log                      TextLog: contacts and warnings in words

A default blueprint (3D view, energy and contact plots, the event log) goes in the file;
at its close a second one opens it paused at the run's first audit finding (the timeline
"from first finding": each step is drawn once the audit has judged it), else at its first
contact ("from first contact", or "from first mesh contact" where the BVH search is
drawn), else at its start; up to LABELLED_SPHERES spheres carry their numbers.
"""

from __future__ import annotations

import math
import uuid
from pathlib import Path

import numpy as np

from ..errors import ViewerError
from ..events import (KIND_MESH, SEARCH_CULLED, SEARCH_REACHED, BroadPhaseInfo, Contacts, EngineWarning, MeshSearch,
                      StepEnd, collision_sums, partner_is_sphere)
from ..engine.periodic import unwrap_near
from .header import RecordingHeader
from . import mesh_view, view
from .view import (contact_centres, describe_contacts, describe_sleep, periodic_faces, scene_bounds, sleep_changed,
                   sphere_colors, up_axis, wall_outlines)

APPLICATION_ID = "physdbg"
IMPULSE_ARROW_SECONDS = 0.05  # an impulse arrow shows how far its velocity change moves a in 50 ms
PATHS_ALL_UP_TO = 2000  # above this many particles, only paths of particles with contacts are drawn
SERIES_BATCH = 128
SEARCHED_SPHERES = 12  # the most spheres whose search of the triangles' BVH is drawn (one tree each)
FIRST_FINDING_TIMELINE = "from first finding"  # a file with an audit finding opens here, paused
FIRST_CONTACT_TIMELINE = "from first contact"  # else here (a scene without meshes)
MESH_CONTACT_TIMELINE = "from first mesh contact"  # a mesh scene's file opens here (paused)
LABELLED_SPHERES = 40  # up to this many spheres are drawn with their numbers
BVH_LEVELS_SHOWN = 3  # levels 0..2 are drawn when the file opens; deeper ones are a click away
# what the 3D view's colours mean (rerun's 3D view has no legend of its own): a text panel
LEGEND = (f"**Spheres** orange, numbered (up to {LABELLED_SPHERES}); grey: immovable; grey-blue: asleep. "
          "**Blue lines**: each sphere's path through the step. **Yellow ghosts**: where each contact happened. "
          "**Green arrows**: contact normals (a radius long). **Red-orange arrows**: impulses (how far the "
          f"velocity change moves the sphere in {IMPULSE_ARROW_SECONDS * 1000:.0f} ms). **Red spheres**: audit "
          f"findings. **Grey lines**: walls; BVH boxes by level under world/bvh (levels 0–{BVH_LEVELS_SHOWN - 1} "
          "shown).")


def viewer_binary() -> str:
    """The Rerun viewer shipped inside rerun-sdk (found even when the venv is not on PATH)."""
    import os

    try:
        import rerun_cli
    except ImportError:
        return "rerun"
    path = os.path.join(os.path.dirname(rerun_cli.__file__), "rerun")
    return path if os.access(path, os.X_OK) else "rerun"


def start_web_viewer(rrd: str | None, web_port: int = 0):
    """The Rerun web viewer (the one rerun-sdk ships) on 127.0.0.1 only, serving ``rrd``
    (or none: a page given ?url= loads one): (the viewer process, its web port, its gRPC
    port). web_port 0: any free one. Raises OSError when it cannot start."""
    import socket
    import subprocess

    ports = []
    for wanted in (web_port, 0):
        with socket.socket() as probe:  # a free port (the gRPC one always: the recording's server)
            probe.bind(("127.0.0.1", wanted))
            ports.append(probe.getsockname()[1])
    web, grpc = ports
    args = [viewer_binary(), *([str(rrd)] if rrd else []), "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port",
            str(web), "--port", str(grpc)]
    process = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    return process, web, grpc


def stop_process(process, grace: float = 10.0) -> None:
    """Terminate a viewer process, killing it after ``grace`` seconds."""
    import subprocess

    if process is not None and process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            process.kill()


def file_sink(path):
    """rerun's FileSink for ``path``, or a RecordingError naming the file when it cannot be
    created (a read-only folder, a missing one rerun will not make)."""
    import rerun as rr

    from ..errors import RecordingError

    try:
        return rr.FileSink(str(path))
    except (RuntimeError, OSError) as err:
        reason = str(err).split(", path:")[0].replace("Failed to create file: ", "")
        raise RecordingError(f"{path}: cannot write the Rerun file ({reason})") from None


class RerunSink:
    """Writes (or streams) the Rerun picture of a run.

    header: the recording's constants; rrd: file to write, or None; spawn: also stream
    to a viewer it starts; detail: "state" | "contacts" | "full" (as the MCAP file).
    Call close() at the end (it flushes the series and the file).
    """

    wants_swept_tests = False  # the view draws states, contacts, the BVH and the meshes' search (observe.py)

    @property
    def wants_mesh_search(self) -> bool:
        """The meshes' search is drawn at detail contacts and full, as the MCAP file keeps it."""
        return self.detail != "state"

    def __init__(self, header: RecordingHeader, rrd: str | Path | None = None, spawn: bool = False,
                 detail: str | None = None, recording_id: str | None = None, stream=None, root: str = "",
                 color: tuple[int, int, int] = view.SPHERE_COLOR, opening: tuple[str, int] | None = None,
                 open_at: int | None = None):
        """color: the moving spheres' colour; opening: (timeline, first step) — every row
        from that step on also carries that sequence timeline, whose first time is where
        a paused viewer opens when the blueprint makes it the active one; open_at: a file
        of its own opens paused at this step (the timeline "from step <k>") instead of at
        its first contact."""
        import rerun as rr

        self.rr = rr
        self.header = header
        self.color = color
        self.opening = opening
        self.root = root.strip("/") + "/" if root else ""  # e.g. "a/": entities under /a/world, /a/stats
        self.detail = detail or header.detail
        # each run its own id (kept in the MCAP file, so a replay is the same recording as
        # the live view), so two runs of one scene open side by side, not merged
        self.shared = stream is not None
        # a run drawn into a recording someone else owns (the diff overlay), or its own
        self.rec = stream if self.shared else rr.RecordingStream(
            APPLICATION_ID, recording_id=recording_id or header.meta.get("run_id") or uuid.uuid4().hex)
        self.rec.set_log_time_enabled(False)  # wall-clock time would make live and replay files differ
        sinks = []
        self.path = Path(rrd) if rrd is not None else None
        if rrd is not None:
            sinks.append(file_sink(rrd))
        if spawn:
            try:
                rr.spawn(connect=False, hide_welcome_screen=True, executable_path=viewer_binary(),
                         recording=self.rec)
            except (RuntimeError, OSError) as err:
                raise ViewerError(f"cannot start the Rerun viewer ({err})") from None
            sinks.append(rr.GrpcSink())
        if not sinks and not self.shared:
            raise ValueError("give an .rrd path, spawn=True, or both")
        if not self.shared:
            self.rec.set_sinks(*sinks)
            self.rec.send_blueprint(blueprint(header, playing=True), make_active=True, make_default=True)
            self.rec.send_recording_name(header.run_name)
        self.radius = header.radius.astype(np.float32)
        self.previous = header.positions.copy()
        self.bvh_levels = 0
        self._series: dict[str, list[float]] = {}
        self._series_steps: list[int] = []
        self._series_times: list[float] = []
        self._contacts: Contacts | None = None
        self._broad_phase: BroadPhaseInfo | None = None
        self._warnings: list[EngineWarning] = []
        self._last_time = (0, 0.0)
        self._virial = 0.0
        self._movable = int(np.count_nonzero(header.inverse_mass > 0))
        self._asleep: np.ndarray | None = None  # the spheres last drawn asleep (None: none)
        # a file of its own opens paused at the first contact (a scene with meshes: the first
        # on a mesh, where the search is drawn): the rows from there on carry the timeline
        # FIRST_CONTACT_TIMELINE (MESH_CONTACT_TIMELINE), and the last blueprint opens it
        self._open_at_first_contact = not self.shared and opening is None
        # ... or, before that, at the first audit finding (FIRST_FINDING_TIMELINE): a step
        # is drawn once the next begins (or at close), when the audit has judged it
        self._open_at_first_finding = self._open_at_first_contact and open_at is None
        self._focus = None  # what the eye frames when the file opens at a finding (view.finding_frame)
        self._held = None  # the step waiting to be drawn: (StepEnd, its per-step events, its findings)
        if open_at is not None and self._open_at_first_contact:
            self.opening = (f"from step {open_at}", int(open_at))
        # each sphere's number beside it, where there are few enough to read
        self._labels = [str(i) for i in range(header.count)] if header.count <= LABELLED_SPHERES else None
        # the meshes' trees (the header's mesh set, built once): drawn by level, and the
        # pre-order positions the recorded search's nodes number
        self._trees = header.walls.meshes.mesh_set if len(header.walls.meshes) else None
        self._search = None  # the step's MeshSearch, drawn at its end
        self._search_drawn = False
        self._ever_searched = False  # a search reached a triangle (else the blueprint says why the panel is empty)
        self._sphere_volumes = False  # a node walked with a sphere was drawn (its entity then logged every step)
        self._log_static(header)

    # ------------------------------------------------------------------ static
    def _log_static(self, h: RecordingHeader) -> None:
        rr, rec = self.rr, self.rec
        up = up_axis(h)
        rec.log(self.root + "world", rr.ViewCoordinates.RIGHT_HAND_Z_UP if up[2] else rr.ViewCoordinates.RIGHT_HAND_Y_UP,
                static=True)
        lo, hi = scene_bounds(h)
        for name, strip in wall_outlines(h.walls, lo, hi):
            rec.log(self.root + f"world/walls/{rr.escape_entity_path_part(name)}", rr.LineStrips3D([strip], colors=[[150, 150, 160]], radii=[-1.5]),
                    static=True)
        meshes = h.walls.meshes
        for k, name in enumerate(meshes.names):  # fixed meshes: translucent grey surfaces with their edges
            corners = meshes.corners[meshes.mesh_of == k].reshape(-1, 3).astype(np.float32)
            path = self.root + f"world/meshes/{rr.escape_entity_path_part(name)}"
            rec.log(path, rr.Mesh3D(vertex_positions=corners,
                                    triangle_indices=np.arange(len(corners), dtype=np.uint32).reshape(-1, 3),
                                    albedo_factor=[170, 170, 185, 140]), static=True)
            edges = corners.reshape(-1, 3, 3)[:, [0, 1, 2, 0]]
            rec.log(path + "/edges", rr.LineStrips3D(list(edges), colors=[[120, 120, 135]], radii=[-0.75]), static=True)
            self._mesh_bvh(path, k)
        for kind, drawing in view.kind_drawings(h.walls):  # a kind declaring its drawing (colliders.kinds.Drawing)
            path = self.root + f"world/{rr.escape_entity_path_part(kind)}"
            if len(drawing.radii):
                rec.log(path + "/spheres", rr.Ellipsoids3D(centers=drawing.centres.astype(np.float32),
                                                           half_sizes=np.repeat(drawing.radii[:, None], 3, axis=1)
                                                           .astype(np.float32),
                                                           colors=[[170, 170, 185]], fill_mode="solid"), static=True)
            if len(drawing.triangles):
                corners = drawing.triangles.reshape(-1, 3).astype(np.float32)
                rec.log(path + "/triangles", rr.Mesh3D(vertex_positions=corners,
                                                       triangle_indices=np.arange(len(corners), dtype=np.uint32)
                                                       .reshape(-1, 3), albedo_factor=[170, 170, 185, 140]),
                        static=True)
        for name, strip in periodic_faces(h.walls, lo, hi):  # faces a sphere passes through: blue, thin
            rec.log(self.root + f"world/periodic/{rr.escape_entity_path_part(name)}", rr.LineStrips3D([strip], colors=[[80, 140, 230]], radii=[-1.0]),
                    static=True)
        self._set_time(0, 0.0)
        rec.log(self.root + "world/spheres", rr.Points3D(np.asarray(h.positions, dtype=np.float32), radii=self.radius,
                                             colors=sphere_colors(h.inverse_mass, moving=self.color),
                                             labels=self._labels, show_labels=self._labels is not None))
        rec.log(self.root + "legend", rr.TextDocument(LEGEND, media_type=rr.MediaType.MARKDOWN), static=True)
        settings = " ".join(f"{key}={value}" for key, value in h.meta.get("settings", {}).items())
        rec.log(self.root + "log", rr.TextLog(f"{h.name}: {h.count} spheres, {len(h.walls)} walls; {settings}", level="INFO"))

    def _set_time(self, frame: int, time: float) -> None:
        self.rec.set_time("step", sequence=frame)
        self.rec.set_time("sim_time", duration=time)
        if self.opening is not None:
            name, first = self.opening
            if frame >= first:
                self.rec.set_time(name, sequence=frame)
            else:
                self.rec.disable_timeline(name)

    def _time_columns(self, frames: list[int], times: list[float]):
        """The index columns of rows at frames (with the opening timeline, when every row
        has it)."""
        rr = self.rr
        index = [rr.TimeColumn("step", sequence=frames), rr.TimeColumn("sim_time", duration=times)]
        if self.opening is not None and frames and frames[0] >= self.opening[1]:
            index.append(rr.TimeColumn(self.opening[0], sequence=frames))
        return index

    # ------------------------------------------------------------------ observer
    def on_event(self, event) -> None:
        if isinstance(event, StepEnd):
            # drawn once the audit has judged it (mark_finding comes right after this)
            step = (event, self._contacts, self._broad_phase, self._warnings, self._search, [])
            self._contacts, self._broad_phase, self._warnings, self._search = None, None, [], None
            self._draw_held()
            self._held = step
        elif isinstance(event, Contacts):
            self._contacts = event
            self._virial = collision_sums(event, self.header.radius)[0]
        elif isinstance(event, EngineWarning):
            self._warnings.append(event)
        elif isinstance(event, BroadPhaseInfo) and self.detail == "full":
            self._broad_phase = event
        elif isinstance(event, MeshSearch) and self.detail != "state":
            self._search = event

    def _end_step(self, end: StepEnd) -> None:
        rr, rec = self.rr, self.rec
        frame = end.step
        self._last_time = (frame, end.time)
        if self._open_at_first_contact and self.opening is None and self._contacts is not None:
            meshes = len(self.header.walls.meshes) > 0
            if np.any(self._contacts.kind == KIND_MESH) if meshes else len(self._contacts) > 0:
                self.opening = (MESH_CONTACT_TIMELINE if meshes else FIRST_CONTACT_TIMELINE, frame)
        self._set_time(frame, end.time)
        # Copies in float32: rerun may hold the array until it flushes. Colours only when the
        # set of sleeping spheres changes: a pile falling asleep turns grey-blue
        changed = sleep_changed(self._asleep, end.asleep)
        # the opening timeline's first row holds the whole style: latest-at on that timeline
        # sees nothing logged before it
        opens = self.opening is not None and frame == self.opening[1]
        colors = sphere_colors(self.header.inverse_mass, end.asleep, self.color) if changed or opens else None
        sleep_lines = describe_sleep(frame, self._asleep, end.asleep) if changed else []
        self._asleep = end.asleep
        rec.log(self.root + "world/spheres",
                rr.Points3D.from_fields(positions=np.asarray(end.positions, dtype=np.float32), colors=colors,
                                        radii=self.radius if opens else None,
                                        labels=self._labels if opens else None,
                                        show_labels=(self._labels is not None) if opens else None))
        contacts = self._contacts if self.detail != "state" else None
        if self._broad_phase is not None:
            self._bvh(self._broad_phase)
            self._broad_phase = None
        self._paths(end, contacts)
        lines = [(f"step {frame}: {warning.message}", "WARN") for warning in self._warnings]
        lines += self._meshes_at(end, contacts)
        if contacts is not None:
            self._draw_contacts(contacts.first(view.DRAWN_CONTACTS_PER_STEP))
            lines += self._describe(frame, contacts, end.dt)
        self._log_lines(frame, end.time, lines + sleep_lines)
        self._warnings = []
        self._contacts = None
        self.previous = end.positions
        self._add_series(frame, end)

    def _draw_held(self) -> None:
        """Draw the step waiting to be drawn, with the findings made on it."""
        if self._held is None:
            return
        end, self._contacts, self._broad_phase, self._warnings, self._search, findings = self._held
        self._held = None
        self._end_step(end)
        for finding in findings:
            self._draw_finding(finding)
        self._contacts, self._broad_phase, self._warnings, self._search = None, None, [], None

    def mark_finding(self, finding) -> None:
        """Mark an audit finding where and when it happened: a red marker in the 3D view
        (world/findings, shown from that step on) and a warning line in the log. A finding
        on the step not drawn yet is drawn with it; the first finding of the run is where a
        file of its own opens (FIRST_FINDING_TIMELINE), before any contact."""
        if self._held is not None and finding.step == self._held[0].step:
            if self._open_at_first_finding:
                self._open_at_first_finding = False
                self.opening = (FIRST_FINDING_TIMELINE, finding.step)
                self._focus = view.finding_frame(self.header, finding)  # the eye frames it
            self._held[5].append(finding)
            return
        self._draw_finding(finding)

    def _draw_finding(self, finding) -> None:
        rr, rec = self.rr, self.rec
        frame = finding.step
        self._set_time(frame, self._time_of(frame))
        if finding.position is not None:
            rec.log(self.root + "world/findings", rr.Points3D([finding.position],
                                                              radii=[view.finding_marker_radius(self.header, finding)],
                                                              colors=[[255, 40, 40, 160]], labels=[finding.kind]))
        self._log_lines(frame, self._time_of(frame), [view.finding_line(finding)])

    def _time_of(self, frame: int) -> float:
        return self._last_time[1] if self._last_time[0] == frame else 0.0

    # ------------------------------------------------------------------ pieces
    def _paths(self, end: StepEnd, contacts: Contacts | None) -> None:
        """One line strip per particle: where it began the step, the centre at each of its
        contacts in order, where it ended. Built as one Arrow array (rerun converts a list
        of small arrays one by one, ~25 µs each)."""
        before, after = self.previous, end.positions
        periodic = self.header.walls.periodic
        if periodic:  # the end was wrapped into the box: draw the path the sphere took
            after = unwrap_near(after, before, self.header.walls.period)
        n = len(after)
        if contacts is not None and len(contacts):
            radius = self.header.radius
            pair = partner_is_sphere(contacts.kind)
            who = np.concatenate([contacts.a, contacts.other[pair]]).astype(np.int64)
            where = np.concatenate([contact_centres(contacts, radius),
                                    contacts.point[pair] - contacts.normal[pair] * radius[contacts.other[pair]][:, None]])
            if periodic:  # b's centre at a contact is next to a, in whichever image a met
                where = unwrap_near(where, before[who], self.header.walls.period)
            order = np.concatenate([np.arange(len(contacts)), np.nonzero(pair)[0]])
            sort = np.lexsort((order, who))
            who, where = who[sort], where[sort]
        else:
            who, where = np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        stops = np.bincount(who, minlength=n)
        chosen = np.arange(n) if n <= PATHS_ALL_UP_TO else np.nonzero(stops)[0]
        lengths = 2 + stops[chosen]
        offsets = np.zeros(len(chosen) + 1, dtype=np.int32)
        np.cumsum(lengths, out=offsets[1:])
        points = np.empty((int(offsets[-1]), 3), dtype=np.float32)
        points[offsets[:-1]] = before[chosen]
        points[offsets[1:] - 1] = after[chosen]
        if len(who):
            slot = np.full(n, -1, dtype=np.int64)
            slot[chosen] = np.arange(len(chosen))
            first_stop = np.searchsorted(who, who)  # index of each particle's first stop in `who`
            rank = np.arange(len(who)) - first_stop
            points[offsets[slot[who]] + 1 + rank] = where
        self.rec.log(self.root + "world/paths", [_line_strips(points, offsets)])
        self.rec.log(self.root + "world/paths", self.rr.LineStrips3D.from_fields(radii=[-1.0], colors=[[90, 170, 255]]))

    def _draw_contacts(self, c: Contacts) -> None:
        rr, rec = self.rr, self.rec
        radius = self.header.radius[c.a] if len(c) else np.zeros(0)
        centres = contact_centres(c, self.header.radius)
        rec.log(self.root + "world/contacts/ghosts", rr.Points3D(centres.astype(np.float32), radii=radius.astype(np.float32),
                                                     colors=[[255, 200, 60, 90]]))
        rec.log(self.root + "world/contacts/normals", rr.Arrows3D(origins=c.point.astype(np.float32),
                                                      vectors=(c.normal * radius[:, None]).astype(np.float32),
                                                      colors=[[80, 220, 120]]))
        inv_mass = self.header.inverse_mass[c.a] if len(c) else np.zeros(0)
        with np.errstate(invalid="ignore"):
            change = c.normal * (c.impulse * inv_mass)[:, None] * IMPULSE_ARROW_SECONDS
        finite = np.all(np.isfinite(change), axis=1)
        rec.log(self.root + "world/contacts/impulses", rr.Arrows3D(origins=c.point[finite].astype(np.float32),
                                                       vectors=change[finite].astype(np.float32),
                                                       colors=[[255, 90, 60]]))

    def _describe(self, frame: int, c: Contacts, dt: float) -> list[tuple[str, str]]:
        lines = describe_contacts(frame, c, dt, self.header.walls.partner_names())
        if len(c) > view.DRAWN_CONTACTS_PER_STEP and len(c) > view.LOG_LINES_PER_STEP:  # the last line counts the rest
            lines[-1] = (lines[-1][0] + f"; ghosts and arrows for the first {view.DRAWN_CONTACTS_PER_STEP}", lines[-1][1])
        return lines

    def _log_lines(self, frame: int, time: float, lines: list[tuple[str, str]]) -> None:
        """All of a step's log lines in one send (one rr.log per line costs ~0.2 ms)."""
        if not lines:
            return
        rr = self.rr
        index = self._time_columns([frame] * len(lines), [time] * len(lines))
        self.rec.send_columns(self.root + "log", indexes=index, columns=rr.TextLog.columns(
            text=[text for text, _ in lines], level=[level for _, level in lines]))

    def _mesh_bvh(self, path: str, k: int) -> None:
        """Mesh k's BVH (the header's mesh set), static, one entity per volume and level (mesh_view.py)."""
        rr, rec, trees = self.rr, self.rec, self._trees
        nodes = trees.nodes_of(k)
        depth = trees.depth[nodes]
        lo, hi, obb, sphere = trees.box_lo[nodes], trees.box_hi[nodes], trees.node_obb[nodes], trees.node_sphere[nodes]
        for level in range(int(depth.max()) + 1):
            at = depth == level
            color = [_level_color(level)]
            rec.log(path + f"/bvh/aabb/level_{level}", rr.Boxes3D(
                centers=(0.5 * (lo[at] + hi[at])).astype(np.float32),
                half_sizes=(0.5 * (hi[at] - lo[at])).astype(np.float32),
                colors=color, radii=[-0.5], fill_mode="majorwireframe"), static=True)
            rec.log(path + f"/bvh/obb/level_{level}", rr.Boxes3D(
                centers=obb[at, :3].astype(np.float32), half_sizes=obb[at, 12:].astype(np.float32),
                quaternions=mesh_view.quaternions(obb[at, 3:12].reshape(-1, 3, 3)).astype(np.float32),
                colors=color, radii=[-0.5], fill_mode="majorwireframe"), static=True)
            rec.log(path + f"/bvh/sphere/level_{level}", rr.Ellipsoids3D(
                centers=sphere[at, :3].astype(np.float32),
                half_sizes=np.repeat(sphere[at, 3:4], 3, axis=1).astype(np.float32),
                colors=color, line_radii=[-0.5], fill_mode="majorwireframe"), static=True)

    def _meshes_at(self, end: StepEnd, contacts: Contacts | None) -> list[tuple[str, str]]:
        """Each kinematic mesh's transform at the step's end, and the step's recorded
        search of the meshes' BVHs (``_draw_search``); the log lines."""
        rr, rec = self.rr, self.rec
        meshes = self.header.walls.meshes
        if not len(meshes):
            return []
        for k, name in enumerate(meshes.names):
            if meshes.moving[k]:
                turn, shift = meshes.transform(k, end.time)
                rec.log(self.root + f"world/meshes/{rr.escape_entity_path_part(name)}",
                        rr.Transform3D(translation=shift.astype(np.float32), mat3x3=turn.astype(np.float32)))
        search, self._search = self._search, None
        if search is None:
            return []
        if self.detail != "full":  # as the MCAP file keeps it: the walks that led to a contact
            search = mesh_view.led_to_contacts(search, contacts, self._trees.leaf_triangle)
        return self._draw_search(end, search, contacts)

    def _draw_search(self, end: StepEnd, search, contacts: Contacts | None) -> list[tuple[str, str]]:
        """The step's recorded walks of the meshes' trees (events.MeshSearch), for the
        spheres it is about (``searched_spheres``): in 3D the nodes met (green) and culled
        (red), each posed with its mesh, the triangles reached (yellow) and the boxes asked
        (grey), and as a tree (search/triangles); the whole step's search under
        world/mesh_search/all (hidden until clicked: a pile's is a solid block). A step that
        walked nothing clears them."""
        rr, rec = self.rr, self.rec
        path = self.root + "world/mesh_search"
        if not len(search.visit_node):
            if self._search_drawn:
                rec.log(path, rr.Clear(recursive=True))
                rec.log(self.root + "search/triangles", rr.Clear(recursive=True))
                self._search_drawn = False
            return []
        self._search_drawn = True
        self._ever_searched = self._ever_searched or bool(np.any(search.visit_outcome == SEARCH_REACHED))
        shown = mesh_view.searched_spheres(search, contacts, SEARCHED_SPHERES)
        rows = np.flatnonzero(np.isin(search.query_sphere[search.visit_query], shown))  # whole walks
        asked = np.flatnonzero(np.isin(search.query_sphere, shown))
        met, culled, triangles = self._draw_visits(path, end, search, rows, asked)
        self._draw_visits(path + "/all", end, search, np.arange(len(search.visit_node)),
                          np.arange(len(search.query_sphere)))
        self._search_graph(search, rows)
        if contacts is None or not np.any(contacts.kind == KIND_MESH):
            return []
        return [(f"step {end.step}: the search of the meshes' BVHs (each in its own frame), as recorded: "
                 f"{len(search.query_sphere)} boxes asked, {len(search.visit_node)} node visits in all; "
                 f"drawn for sphere{'s' if len(shown) != 1 else ''} {', '.join(str(i) for i in shown)}: "
                 f"{len(met)} nodes met (green), {len(culled)} culled (red), {len(triangles)} triangles reached "
                 f"(yellow), the search tree below (the whole step's under world/mesh_search/all)", "INFO")]

    def _draw_visits(self, path: str, end: StepEnd, search, rows: np.ndarray, asked: np.ndarray):
        """Draw the visits ``rows`` and the boxes ``asked`` of a search under ``path``;
        returns the nodes met, the nodes culled (met by none) and the triangles reached."""
        rr, rec = self.rr, self.rec
        meshes, trees = self.header.walls.meshes, self._trees
        outcome, node = search.visit_outcome[rows], search.visit_node[rows].astype(np.int64)
        met = np.unique(node[outcome != SEARCH_CULLED])
        culled = np.setdiff1d(np.unique(node[outcome == SEARCH_CULLED]), met)
        triangles = np.unique(trees.leaf_triangle[node[outcome == SEARCH_REACHED]])
        for part, which, color in (("met", met, [60, 220, 90]), ("culled", culled, [230, 70, 60])):
            (centers, half_sizes, quaternions), (sphere_centers, sphere_radii) = _posed_nodes(trees, which, end.time)
            rec.log(path + f"/{part}", rr.Boxes3D(
                centers=centers, half_sizes=half_sizes, quaternions=quaternions,
                colors=[color], radii=[-1.5 if part == "met" else -0.75], fill_mode="majorwireframe"))
            if len(sphere_centers) or self._sphere_volumes:  # a mesh walked with spheres: its nodes as spheres
                self._sphere_volumes = True
                rec.log(path + f"/{part}_spheres", rr.Ellipsoids3D(
                    centers=sphere_centers, half_sizes=np.repeat(sphere_radii[:, None], 3, axis=1),
                    colors=[color], line_radii=[-0.75], fill_mode="majorwireframe"))
        corners = meshes.placed(end.time)[0][triangles].reshape(-1, 3).astype(np.float32)
        rec.log(path + "/triangles", rr.Mesh3D(
            vertex_positions=corners, triangle_indices=np.arange(len(corners), dtype=np.uint32).reshape(-1, 3),
            albedo_factor=[250, 210, 40, 220]))
        lo, hi = search.query_lo[asked], search.query_hi[asked]
        rec.log(path + "/queries", rr.Boxes3D(centers=(0.5 * (lo + hi)).astype(np.float32),
                                              half_sizes=(0.5 * (hi - lo)).astype(np.float32),
                                              colors=[[170, 170, 190]], radii=[-0.5], fill_mode="majorwireframe"))
        return met, culled, triangles

    def _search_graph(self, search, rows: np.ndarray) -> None:
        """The search tree as a graph (search/triangles): a node per visit in ``rows``
        (whole walks), green where the box met the node, red where the branch ended, yellow
        at a triangle reached; an edge from each visit to those reached from it."""
        rr = self.rr
        meshes, leaf_triangle = self.header.walls.meshes, self._trees.leaf_triangle
        spheres = search.query_sphere
        new_row = np.full(len(search.visit_node), -1, dtype=np.int64)
        new_row[rows] = np.arange(len(rows))
        parent = search.visit_parent[rows]
        visits = np.stack([search.visit_query[rows], search.visit_node[rows], search.visit_outcome[rows],
                           np.where(parent >= 0, new_row[np.maximum(parent, 0)], -1)], axis=1).astype(np.int64)
        ids = [f"{j}:{q}" for j, q, _o, _p in visits.tolist()]
        labels = []
        for j, q, outcome, parent_row in visits.tolist():
            what = meshes.triangle_words(int(leaf_triangle[q])) if outcome == SEARCH_REACHED else f"node {q}"
            after = int(search.query_after[j])
            # contacts numbered from 1 within the step, as every report numbers them
            asked = f"sphere {int(spheres[j])}" + (f" after contact {after + 1}" if after >= 0 else "")
            labels.append(f"{asked}: {what}" if parent_row < 0 else what)
        colors = [[(60, 200, 90), (230, 70, 60), (250, 210, 40)][o] for o in visits[:, 2].tolist()]
        position = mesh_view.tree_layout(visits) * [110.0, 70.0]
        path = self.root + "search/triangles"
        self.rec.log(path, rr.GraphNodes(ids, labels=labels, colors=colors, positions=position.astype(np.float32)))
        edges = [(ids[p], ids[row]) for row, p in enumerate(visits[:, 3].tolist()) if p >= 0]
        self.rec.log(path, rr.GraphEdges(edges, graph_type="directed"))

    def _bvh(self, info: BroadPhaseInfo) -> None:
        rr, rec = self.rr, self.rec
        nodes = info.nodes
        if nodes is None:
            return
        depth = nodes["depth"]
        levels = int(depth.max()) + 1 if len(depth) else 0
        for level in range(max(levels, self.bvh_levels)):
            at = depth == level
            lo, hi = nodes["lo"][at], nodes["hi"][at]
            rec.log(self.root + f"world/bvh/level_{level}", rr.Boxes3D(
                centers=((lo + hi) * 0.5).astype(np.float32), half_sizes=((hi - lo) * 0.5).astype(np.float32),
                colors=[_level_color(level)], radii=[-0.5], fill_mode="majorwireframe"))
        self.bvh_levels = max(levels, self.bvh_levels)

    def _add_series(self, frame: int, end: StepEnd) -> None:
        values = {
            "stats/energy/kinetic": end.kinetic, "stats/energy/potential": end.potential,
            "stats/energy/total": end.kinetic + end.potential,
            "stats/momentum/x": end.momentum[0], "stats/momentum/y": end.momentum[1],
            "stats/momentum/z": end.momentum[2],
            "stats/contacts": end.counts.contacts,
            # a pile's churn: contacts the rapid rule held, held contacts let go again
            "stats/rapid": end.counts.rapid, "stats/released": end.counts.released,
        }
        if self.header.sleeping:  # spheres asleep (sleep.py); with sleeping off it is 0: not drawn
            values["stats/asleep"] = end.counts.asleep
        # Z = PV/NkT of this step, from its collisions; NaN (a gap) where no sphere moves, so
        # that every series keeps one value a step (rerun refuses columns of unequal length,
        # and did drop a batch once a pile fell asleep)
        if self._movable > 1:
            values["stats/pressure/z"] = (1 + self._virial / (2 * end.kinetic * end.dt) if end.kinetic > 0
                                          else math.nan)
        self._virial = 0.0
        for path, value in values.items():
            self._series.setdefault(path, []).append(float(value))
        self._series_steps.append(frame)
        self._series_times.append(end.time)
        if len(self._series_steps) >= SERIES_BATCH:
            self._send_series()

    def _send_series(self) -> None:
        rr = self.rr
        if not self._series_steps:
            return
        # rows before the opening step and from it on are sent apart: an index column
        # covers every row of a send
        split = 0 if self.opening is None else int(np.searchsorted(self._series_steps, self.opening[1]))
        for part in (slice(0, split), slice(split, None)):
            steps, times = self._series_steps[part], self._series_times[part]
            if not steps:
                continue
            index = self._time_columns(steps, times)
            for path, values in self._series.items():
                self.rec.send_columns(self.root + path, indexes=index, columns=rr.Scalars.columns(scalars=values[part]))
        self._series = {}
        self._series_steps = []
        self._series_times = []

    def _flush_or_give_up(self) -> None:
        """rerun's flush, bounded: it waits forever once its file writer has died (a full
        disk: rerun only logs the failed write). Waited for a second at a time while the
        file still grows; FLUSH_IDLE_SECONDS without growth (or FLUSH_SECONDS in all) and
        the stream is abandoned with an error."""
        import time

        started, last_size, grew_at = time.perf_counter(), -1, time.perf_counter()
        while True:
            try:
                self.rec.flush(timeout_sec=1.0)
                return
            except Exception as err:  # rerun raises its own error type on the timeout
                now = time.perf_counter()
                size = self.path.stat().st_size if self.path is not None and self.path.exists() else -1
                if size > last_size:
                    last_size, grew_at = size, now
                if now - grew_at < FLUSH_IDLE_SECONDS and now - started < FLUSH_SECONDS:
                    time.sleep(0.5)  # a dead writer makes flush fail at once: no busy loop
                    continue
                _abandon(self.rec)
                raise OSError(f"the Rerun file {self.path or ''} could not be written ({err}; it stopped growing "
                              f"{now - grew_at:.0f} s ago): is the disk full?") from None

    def close(self) -> None:
        self._draw_held()
        self._send_series()
        if self.shared:
            return
        if self._open_at_first_contact:  # at the first finding or contact, or paused at the start
            why_empty = None
            if len(self.header.walls.meshes) and not self._ever_searched:
                why_empty = ("not recorded at --detail state" if self.detail == "state" else
                             "no sphere's path reached a mesh's triangles in this run")
            self.rec.send_blueprint(blueprint(self.header, self.opening, search_empty=why_empty,
                                              focus=self._focus), make_active=True,
                                    make_default=True)
        self._flush_or_give_up()
        self.rec.disconnect()
        if self.path is not None and not rrd_is_whole(self.path):
            # rerun's file writer reports a failed write (a full disk) only in its own log
            raise OSError(f"the Rerun file {self.path} ends before its footer: a write failed (is the disk full?)")


def _posed_nodes(trees, nodes: np.ndarray, time: float):
    """The walked volumes of ``nodes`` (pre-order positions of a mesh set's trees,
    engine/mesh/mesh_set.MeshSet), each in
    its mesh's frame, posed where the mesh is at run time ``time`` (a fixed mesh's frame is
    the world): (boxes: centres (K, 3), half sizes (K, 3), rotations (K, 4 quaternions,
    x y z w), of the nodes walked with an AABB or an OBB; spheres: centres (S, 3), radii
    (S,), of those walked with a sphere), float32."""
    from scipy.spatial.transform import Rotation

    from ..engine.mesh.tree import OBB, SPHERE

    meshes = trees.meshes
    owner = trees.node_mesh[nodes]
    volume = trees.volume[owner]
    lo, hi, obb, sphere = trees.box_lo[nodes], trees.box_hi[nodes], trees.node_obb[nodes], trees.node_sphere[nodes]
    is_obb, is_sphere = volume == OBB, volume == SPHERE
    centers = np.where(is_obb[:, None], obb[:, :3], 0.5 * (lo + hi))
    half = np.where(is_obb[:, None], obb[:, 12:], 0.5 * (hi - lo))
    turns = np.tile(np.eye(3), (len(nodes), 1, 1))
    turns[is_obb] = np.transpose(obb[is_obb, 3:12].reshape(-1, 3, 3), (0, 2, 1))  # columns: the axes
    turns[np.linalg.det(turns) < 0, :, 2] *= -1.0  # a PCA frame may be reflected: the box is the same
    sphere_centers = sphere[:, :3].copy()
    for k in np.unique(owner[meshes.moving[owner]]) if len(nodes) else []:
        rows = owner == k
        turn, shift = meshes.transform(int(k), time)
        centers[rows] = centers[rows] @ turn.T + shift
        sphere_centers[rows] = sphere_centers[rows] @ turn.T + shift
        turns[rows] = turn @ turns[rows]
    boxes = ~is_sphere
    quaternions = Rotation.from_matrix(turns[boxes]).as_quat() if boxes.any() else np.zeros((0, 4))
    return ((centers[boxes].astype(np.float32), half[boxes].astype(np.float32), quaternions.astype(np.float32)),
            (sphere_centers[is_sphere].astype(np.float32), sphere[is_sphere, 3].astype(np.float32)))


FLUSH_SECONDS = 600.0  # the most closing a Rerun file may wait for its writer, growing or not
FLUSH_IDLE_SECONDS = 5.0  # ... and without the file growing: then its writer is taken for dead
_ABANDONED: list = []  # recording streams whose file writer died, kept alive (see _abandon)


def _abandon(rec) -> None:
    """Leave a recording stream whose file writer died (rerun 0.41 only logs the failed
    write): its disconnect, any sink swap and even its ``__del__`` wait forever for that
    writer, and so does rerun's flush of every stream at exit. Its ``__del__`` is skipped
    and that exit hook removed (the stream is leaked until the process ends), so physdbg
    reports the error and exits instead of hanging."""
    cls = type(rec)
    if not getattr(cls, "_physdbg_guarded", False):
        original = cls.__del__

        def __del__(self, abandoned=_ABANDONED):  # noqa: N807 - rerun's own hook, wrapped
            # the list is bound here: at interpreter exit the module's globals may be None
            if not any(self is dead for dead in abandoned):
                original(self)

        cls.__del__ = __del__
        cls._physdbg_guarded = True
    _ABANDONED.append(rec)  # held, so it is never freed and its id never reused
    import atexit

    import rerun

    atexit.unregister(rerun.rerun_shutdown)  # it flushes every stream at exit: this one forever


RRD_FOOTER = b"RRF2FOOT"  # how an .rrd file rerun finished writing ends (then a 4-byte version)


def rrd_is_whole(path: Path) -> bool:
    """Whether rerun finished writing the .rrd file: it ends in the footer its encoder
    writes last (a write that failed, on a full disk, leaves the file without it)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, 2)
            size = f.tell()
            f.seek(max(size - 64, 0))
            return RRD_FOOTER in f.read()
    except OSError:
        return False


# ----------------------------------------------------------------------------- blueprint
def blueprint(header: RecordingHeader, opening: tuple[str, int] | None = None, search_empty: str | None = None,
              playing: bool = False, focus: tuple[np.ndarray, float] | None = None):
    """3D view of the world beside the energy and contact plots and the event log; the
    camera looks at the whole scene from above and to the side, up against gravity.
    opening: (timeline, step) to open on, paused (else the step timeline, at its start:
    paused, or playing for a live view that has not chosen yet); search_empty: why a
    mesh scene's search panel is empty (it says so in its title); focus: what the eye
    frames instead of the whole scene (camera)."""
    import rerun.blueprint as rrb

    # a mesh scene's view shares its column with the search tree: the eye comes closer
    eye = camera(header, distance=1.0 if len(header.walls.meshes) else 1.4, focus=focus)
    scene = rrb.Spatial3DView(origin="/world", name="scene", eye_controls=eye, overrides={
        **{f"/world/bvh/level_{level}": rrb.EntityBehavior(visible=False) for level in range(BVH_LEVELS_SHOWN, 64)},
        **hidden_mesh_volumes(header),
        "/world/mesh_search/all": rrb.EntityBehavior(visible=False)})
    if len(header.walls.meshes):  # the search tree under the scene, as wide
        title = (f"the BVH search: {search_empty}" if search_empty else
                 "the step's BVH search, as recorded (green: met, red: culled, yellow: triangle)")
        scene = rrb.Vertical(scene, rrb.GraphView(origin="/search", name=title), row_shares=[3, 2])
    return rrb.Blueprint(
        rrb.Horizontal(
            scene,
            rrb.Vertical(
                rrb.TimeSeriesView(origin="/stats/energy", name="energy (J)"),
                rrb.TimeSeriesView(origin="/stats", contents=["/stats/contacts", "/stats/rapid", "/stats/released",
                                                              *(["/stats/asleep"] if header.sleeping else [])],
                                   name="contacts per step (all, rapid, released)"
                                        + ("; spheres asleep" if header.sleeping else "")),
                rrb.TextLogView(origin="/log", name="events"),
                rrb.TextDocumentView(origin="/legend", name="legend"),
                row_shares=[2, 1, 2, 1],
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline=opening[0], play_state="paused") if opening else
        rrb.TimePanel(timeline="step", play_state="playing" if playing else "paused"),
        collapse_panels=True,
    )


def hidden_mesh_volumes(header: RecordingHeader, root: str = "") -> dict:
    """Blueprint overrides: of each mesh's BVH only the volume its run walked
    (Meshes.bounding_volume) is shown, its first BVH_LEVELS_SHOWN levels; the other two
    volumes and the deeper levels are hidden (all a click away in the view's entity tree).
    root: the run's entity root ("/a" in the diff overlay)."""
    import rerun as rr
    import rerun.blueprint as rrb

    hidden = {}
    meshes = header.walls.meshes
    walked = list(getattr(meshes, "bounding_volume", None) or ["aabb"] * len(meshes.names))
    for name, used in zip(meshes.names, walked, strict=True):
        path = f"{root}/world/meshes/{rr.escape_entity_path_part(name)}/bvh"
        for volume in ("aabb", "obb", "sphere"):
            if volume != used:
                hidden[f"{path}/{volume}"] = rrb.EntityBehavior(visible=False)
        for level in range(BVH_LEVELS_SHOWN, 64):
            hidden[f"{path}/{used}/level_{level}"] = rrb.EntityBehavior(visible=False)
    return hidden


def camera(header: RecordingHeader, distance: float = 1.4, focus: tuple[np.ndarray, float] | None = None):
    """The 3D view's eye: on the whole scene, from above and to the side, up against
    gravity (every view of a scene framed alike, so two runs side by side line up);
    distance: from the scene's centre, in the scene box's diagonals. focus: (centre (3,),
    extent m) to frame instead (a finding the file opens at: view.finding_frame), from
    the same side."""
    import rerun.blueprint as rrb

    lo, hi = scene_bounds(header)
    centre = (lo + hi) / 2
    if focus is not None:
        centre = np.asarray(focus[0], dtype=float)
        lo, hi = centre - focus[1] / 2, centre + focus[1] / 2
    up = up_axis(header)
    helper = np.array([0.0, 0.0, 1.0]) if not up[2] else np.array([0.0, -1.0, 0.0])
    side = np.cross(up, helper)
    front = np.cross(side, up)
    direction = front + 0.55 * side + 0.45 * up
    eye = centre + direction / np.linalg.norm(direction) * distance * float(np.linalg.norm(hi - lo))
    return rrb.EyeControls3D(position=eye.tolist(), look_target=centre.tolist(), eye_up=up.tolist())


# ----------------------------------------------------------------------------- geometry
class _ArrowBatch:
    def __init__(self, array):
        self.array = array

    def as_arrow_array(self):
        return self.array


def _line_strips(points: np.ndarray, offsets: np.ndarray):
    """LineStrips3D strips from (P, 3) float32 points and (M+1,) int32 offsets, as one Arrow array."""
    import pyarrow as pa
    import rerun as rr

    values = pa.FixedSizeListArray.from_arrays(pa.array(points.reshape(-1), type=pa.float32()), 3)
    strips = pa.ListArray.from_arrays(pa.array(offsets, type=pa.int32()), values)
    strips = strips.cast(rr.components.LineStrip3DBatch([]).as_arrow_array().type)
    return rr.DescribedComponentBatch(_ArrowBatch(strips), rr.LineStrips3D.descriptor_strips())


def _level_color(level: int) -> list[int]:
    palette = [[255, 255, 255], [255, 120, 120], [120, 255, 120], [120, 160, 255], [255, 220, 100],
               [220, 120, 255], [100, 230, 230]]
    return palette[level % len(palette)]
