"""The view channels of an MCAP recording: the run in Foxglove's published schemas.

What Foxglove's 3D, Plot and Log panels (and rerun's MCAP importer) show without knowing
anything of physdbg; docs/foxglove-layout.json arranges them like the Rerun blueprint.

    /view/transform  foxglove.FrameTransform  frame 0: the scene's frame ("scene") in
                     Foxglove's z-up "world" (a quarter turn about x when gravity is -y)
    /view/scene      foxglove.SceneUpdate     frame 0: the walls (outline and a faint face,
                     entity "walls") and each mesh (its triangles, translucent,
                     entity "mesh <name>"; a kinematic mesh's again each frame, posed); every frame: one entity per sphere ("sphere 17", a
                     SpherePrimitive of its diameter) and, at detail contacts or full,
                     entity "contacts": an arrow along each contact normal at its point
                     (length = the sphere's radius; the first DRAWN_CONTACTS_PER_STEP);
                     a scene with meshes at detail contacts or full, entity "mesh search":
                     the step's recorded search of the meshes' BVHs by the spheres it is
                     about (nodes met green, culled red, triangles reached yellow)
    /view/points     foxglove.PointCloud      every frame: the sphere centres, fields x, y,
                     z, radius (float32) and id (uint32)
    /view/log        foxglove.Log             the run in words: the scene, each step's first
                     contacts (detail contacts or full) and every warning

Every message's timestamp is its MCAP log time (the frame's simulated time).
"""

from __future__ import annotations

import numpy as np

from ..events import SEARCH_CULLED, SEARCH_REACHED, Contacts, EngineWarning, StepEnd
from . import format as fmt
from . import view
from .header import RecordingHeader
from .scene_wire import SphereEntities, arrows, entity_field

SEARCHED_SPHERES = 12  # the most spheres whose walks the "mesh search" entity draws

# float32 centres, as both viewers draw them (half the bytes of float64; the exact values
# are in /physdbg/state)
POINT_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("radius", "<f4"), ("id", "<u4")])
LOG_LEVELS = {"DEBUG": 1, "INFO": 2, "WARN": 3}


def view_schemas() -> dict[str, type]:
    """topic -> Foxglove protobuf class of each view channel."""
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from foxglove_schemas_protobuf.Log_pb2 import Log
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    return {fmt.TOPIC_VIEW_SCENE: SceneUpdate, fmt.TOPIC_VIEW_POINTS: PointCloud, fmt.TOPIC_VIEW_LOG: Log,
            fmt.TOPIC_VIEW_TRANSFORM: FrameTransform}


class FoxgloveView:
    """Builds the view messages of a run: ``first(ns)`` for frame 0, ``step(...)`` for each
    step; each returns [(topic, serialized message), ...]."""

    def __init__(self, header: RecordingHeader, detail: str):
        self.header = header
        self.detail = detail
        self.classes = view_schemas()
        self._asleep: np.ndarray | None = None
        self._findings = 0  # audit findings marked so far (each its own entity)
        self._spheres_wire = SphereEntities(fmt.VIEW_SCENE_FRAME, 2.0 * header.radius, self._sphere_rgba(None))
        self._points = np.zeros(header.count, dtype=POINT_DTYPE)
        self._points["radius"] = header.radius
        self._points["id"] = np.arange(header.count)

    def _sphere_rgba(self, asleep: np.ndarray | None) -> np.ndarray:
        """(N, 4) each sphere's colour in [0, 1], opaque; grey-blue while asleep ((N,) bool or None)."""
        rgb = view.sphere_colors(self.header.inverse_mass, asleep)
        rgba = np.ones((len(rgb), 4))
        rgba[:, :3] = np.asarray(rgb, dtype=np.float64) / 255.0
        return rgba

    # ------------------------------------------------------------------ frames
    def first(self, ns: int) -> list[tuple[str, bytes]]:
        h = self.header
        settings = " ".join(f"{key}={value}" for key, value in h.meta.get("settings", {}).items())
        return [
            (fmt.TOPIC_VIEW_TRANSFORM, self._transform(ns)),
            (fmt.TOPIC_VIEW_SCENE, self._walls(ns)),
            (fmt.TOPIC_VIEW_SCENE, self._spheres(ns, h.positions)),
            (fmt.TOPIC_VIEW_POINTS, self._point_cloud(ns, h.positions)),
            *self._log(ns, [(f"{h.name}: {h.count} spheres, {len(h.walls)} walls; {settings}", "INFO")]),
        ]

    def step(self, frame: int, ns: int, end: StepEnd, contacts: Contacts | None,
             warnings: list[EngineWarning], search=None) -> list[tuple[str, bytes]]:
        """search: the step's recorded search of the meshes' trees (events.MeshSearch, as
        the file keeps it), or None."""
        sleep_lines = []
        if view.sleep_changed(self._asleep, end.asleep):
            self._spheres_wire.set_colors(self._sphere_rgba(end.asleep))
            sleep_lines = view.describe_sleep(frame, self._asleep, end.asleep)
        self._asleep = end.asleep
        out = [(fmt.TOPIC_VIEW_SCENE, self._spheres(ns, end.positions, contacts))]
        moving = np.flatnonzero(self.header.walls.meshes.moving)
        if len(moving):  # kinematic meshes, where they are at the frame's time
            update = self.classes[fmt.TOPIC_VIEW_SCENE]()
            for k in moving.tolist():
                self._mesh(update, k, ns, end.time)
            out.append((fmt.TOPIC_VIEW_SCENE, update.SerializeToString()))
        if len(self.header.walls.meshes) and self.detail != "state":
            update = self.classes[fmt.TOPIC_VIEW_SCENE]()
            update.entities.append(self._search(ns, search, end.time, contacts))
            out.append((fmt.TOPIC_VIEW_SCENE, update.SerializeToString()))
        out.append((fmt.TOPIC_VIEW_POINTS, self._point_cloud(ns, end.positions)))
        lines = [(f"step {frame}: {w.message}", "WARN") for w in warnings]
        if contacts is not None:
            lines += view.describe_contacts(frame, contacts, end.dt, self.header.walls.partner_names())
        lines += sleep_lines
        out += self._log(ns, lines)
        return out

    def finding(self, ns: int, finding) -> list[tuple[str, bytes]]:
        """An audit finding: its warning line, and a red translucent sphere where it happened
        (entity finding-<n>, kept from then on) when it has one place."""
        out = self._log(ns, [view.finding_line(finding)])
        if finding.position is not None:
            self._findings += 1
            update = self.classes[fmt.TOPIC_VIEW_SCENE]()
            entity = update.entities.add(id=f"finding-{self._findings}", frame_id=fmt.VIEW_SCENE_FRAME)
            entity.timestamp.FromNanoseconds(ns)
            entity.metadata.add(key="kind", value=finding.kind)
            size = 2 * view.finding_marker_radius(self.header, finding)  # a diameter
            sphere = entity.spheres.add()
            sphere.pose.position.x, sphere.pose.position.y, sphere.pose.position.z = (float(c) for c in
                                                                                        finding.position)
            sphere.pose.orientation.w = 1.0
            sphere.size.x = sphere.size.y = sphere.size.z = size
            sphere.color.r, sphere.color.g, sphere.color.b, sphere.color.a = 1.0, 0.16, 0.16, 0.6
            out.append((fmt.TOPIC_VIEW_SCENE, update.SerializeToString()))
        return out

    # ------------------------------------------------------------------ messages
    def _transform(self, ns: int) -> bytes:
        message = self.classes[fmt.TOPIC_VIEW_TRANSFORM](parent_frame_id=fmt.VIEW_WORLD_FRAME,
                                                          child_frame_id=fmt.VIEW_SCENE_FRAME)
        message.timestamp.FromNanoseconds(ns)
        rotation = message.rotation
        if view.up_axis(self.header)[2]:
            rotation.w = 1.0
        else:  # a quarter turn about x takes the engine's +y (up) to Foxglove's +z
            rotation.x, rotation.w = np.sqrt(0.5), np.sqrt(0.5)
        return message.SerializeToString()

    def _walls(self, ns: int) -> bytes:
        from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive

        update = self.classes[fmt.TOPIC_VIEW_SCENE]()
        entity = update.entities.add(id="walls", frame_id=fmt.VIEW_SCENE_FRAME)
        entity.timestamp.FromNanoseconds(ns)
        lo, hi = view.scene_bounds(self.header)
        for name, outline in view.wall_outlines(self.header.walls, lo, hi):
            line = entity.lines.add(type=LinePrimitive.LINE_STRIP, thickness=2.0, scale_invariant=True)
            line.pose.orientation.w = 1.0
            line.color.r, line.color.g, line.color.b, line.color.a = 0.6, 0.6, 0.65, 1.0
            for x, y, z in outline.tolist():
                line.points.add(x=x, y=y, z=z)
            face = entity.triangles.add()
            face.pose.orientation.w = 1.0
            face.color.r, face.color.g, face.color.b, face.color.a = 0.6, 0.6, 0.65, 0.12
            for corner in (0, 1, 2, 0, 2, 3):
                x, y, z = outline[corner].tolist()
                face.points.add(x=x, y=y, z=z)
            entity.metadata.add(key="wall", value=name)
        for name, outline in view.periodic_faces(self.header.walls, lo, hi):  # outlines only, blue
            line = entity.lines.add(type=LinePrimitive.LINE_STRIP, thickness=1.0, scale_invariant=True)
            line.pose.orientation.w = 1.0
            line.color.r, line.color.g, line.color.b, line.color.a = 0.3, 0.55, 0.9, 1.0
            for x, y, z in outline.tolist():
                line.points.add(x=x, y=y, z=z)
            entity.metadata.add(key="periodic face", value=name)
        for k in range(len(self.header.walls.meshes)):  # each mesh: its triangles, translucent
            self._mesh(update, k, ns, 0.0)
        for kind, drawing in view.kind_drawings(self.header.walls):  # a kind declaring its drawing
            partners = update.entities.add(id=kind, frame_id=fmt.VIEW_SCENE_FRAME)
            partners.timestamp.FromNanoseconds(ns)
            for centre, radius in zip(drawing.centres.tolist(), drawing.radii.tolist(), strict=True):
                ball = partners.spheres.add()
                ball.pose.position.x, ball.pose.position.y, ball.pose.position.z = centre
                ball.pose.orientation.w = 1.0
                ball.size.x = ball.size.y = ball.size.z = 2.0 * radius
                ball.color.r, ball.color.g, ball.color.b, ball.color.a = 0.67, 0.67, 0.72, 0.55
            if len(drawing.triangles):
                surface = partners.triangles.add()
                surface.pose.orientation.w = 1.0
                surface.color.r, surface.color.g, surface.color.b, surface.color.a = 0.67, 0.67, 0.72, 0.55
                for x, y, z in drawing.triangles.reshape(-1, 3).tolist():
                    surface.points.add(x=x, y=y, z=z)
        return update.SerializeToString()

    def _mesh(self, update, k: int, ns: int, time: float) -> None:
        """Entity "mesh <name>": mesh k's triangles as they were at run time 0, posed where
        the mesh is at ``time`` (a kinematic mesh's entity is sent again every frame)."""
        from .mesh_view import quaternions

        meshes = self.header.walls.meshes
        name = meshes.names[k]
        mesh = update.entities.add(id=f"mesh {name}", frame_id=fmt.VIEW_SCENE_FRAME)
        mesh.timestamp.FromNanoseconds(ns)
        surface = mesh.triangles.add()
        turn, shift = meshes.transform(k, time)
        q = surface.pose.orientation
        q.x, q.y, q.z, q.w = quaternions(turn.T[None])[0].tolist()
        p = surface.pose.position
        p.x, p.y, p.z = shift.tolist()
        surface.color.r, surface.color.g, surface.color.b, surface.color.a = 0.67, 0.67, 0.72, 0.55
        for x, y, z in meshes.corners[meshes.mesh_of == k].reshape(-1, 3).tolist():
            surface.points.add(x=x, y=y, z=z)
        mesh.metadata.add(key="mesh", value=name)

    def _search(self, ns: int, search, time: float, contacts: Contacts | None):
        """Entity "mesh search": the step's recorded search of the meshes' BVHs by the
        spheres it is about (mesh_view.searched_spheres, as the Rerun view draws it), each
        mesh's part posed where the mesh is at ``time``: the edges of the nodes met (green)
        and culled (red), the triangles reached (yellow); its metadata the spheres drawn and
        the whole search's counts (the rest is in /physdbg/mesh_search). Empty when nothing
        was walked (it replaces the last step's)."""
        from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
        from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity

        from . import mesh_view

        entity = SceneEntity(id="mesh search", frame_id=fmt.VIEW_SCENE_FRAME)
        entity.timestamp.FromNanoseconds(ns)
        if search is None or not len(search.visit_node):
            return entity
        from ..engine.mesh.tree import SPHERE

        meshes = self.header.walls.meshes
        trees = meshes.mesh_set  # the header's, built once: the recorded nodes are its pre-order positions
        shown = mesh_view.searched_spheres(search, contacts, SEARCHED_SPHERES)
        mine = np.isin(search.query_sphere[search.visit_query], shown)
        node, outcome = search.visit_node[mine].astype(np.int64), search.visit_outcome[mine]
        met = np.unique(node[outcome != SEARCH_CULLED])
        culled = np.setdiff1d(np.unique(node[outcome == SEARCH_CULLED]), met)
        reached = np.unique(trees.leaf_triangle[node[outcome == SEARCH_REACHED]])
        for k in range(len(meshes)):
            turn, shift = meshes.transform(k, time)
            rotation = mesh_view.quaternions(turn.T[None])[0].tolist()
            for nodes, color in ((met, (0.24, 0.86, 0.35, 1.0)), (culled, (0.9, 0.27, 0.24, 0.8))):
                mine = nodes[trees.node_mesh[nodes] == k]
                if not len(mine):
                    continue
                if trees.volume[k] == SPHERE:  # the nodes' spheres
                    for x, y, z, r in trees.node_sphere[mine].tolist():
                        ball = entity.spheres.add()
                        ball.pose.orientation.w = 1.0
                        ball.pose.position.x, ball.pose.position.y, ball.pose.position.z = (
                            (turn @ np.array([x, y, z]) + shift).tolist())
                        ball.size.x = ball.size.y = ball.size.z = 2.0 * r
                        ball.color.r, ball.color.g, ball.color.b, ball.color.a = color[:3] + (0.25,)
                    continue
                line = entity.lines.add(type=LinePrimitive.LINE_LIST, thickness=1.5, scale_invariant=True)
                q = line.pose.orientation
                q.x, q.y, q.z, q.w = rotation
                line.pose.position.x, line.pose.position.y, line.pose.position.z = shift.tolist()
                line.color.r, line.color.g, line.color.b, line.color.a = color
                corners, edges = _box_edges(*_node_boxes(trees, mine, k))
                for x, y, z in corners.tolist():
                    line.points.add(x=x, y=y, z=z)
                line.indices.extend(edges.tolist())
            mine = reached[meshes.mesh_of[reached] == k]
            if len(mine):
                face = entity.triangles.add()
                q = face.pose.orientation
                q.x, q.y, q.z, q.w = rotation
                face.pose.position.x, face.pose.position.y, face.pose.position.z = shift.tolist()
                face.color.r, face.color.g, face.color.b, face.color.a = 0.98, 0.82, 0.16, 0.85
                for x, y, z in meshes.corners[mine].reshape(-1, 3).tolist():
                    face.points.add(x=x, y=y, z=z)
        entity.metadata.add(key="spheres drawn", value=" ".join(str(i) for i in shown))
        everything = search.visit_outcome
        for key, value in (("boxes asked", len(search.query_sphere)), ("node visits", len(everything)),
                           ("nodes met", len(np.unique(search.visit_node[everything != SEARCH_CULLED]))),
                           ("triangles reached", len(np.unique(search.visit_node[everything == SEARCH_REACHED])))):
            entity.metadata.add(key=key, value=str(value))
        return entity

    def _spheres(self, ns: int, positions: np.ndarray, contacts: Contacts | None = None) -> bytes:
        """One entity per sphere (a stable id Foxglove shows on a click) and, at detail
        contacts or full, entity "contacts": both written with numpy (scene_wire)."""
        data = self._spheres_wire.encode(ns, positions)
        if self.detail != "state":
            data += entity_field(self._arrows(ns, contacts))
        return data

    def _arrows(self, ns: int, contacts: Contacts | None):
        """Entity "contacts": an arrow along each drawn contact's normal (none at frame 0),
        the sphere's radius long, blue where the contact is held or resting."""
        entity = self.classes[fmt.TOPIC_VIEW_SCENE]().entities.add(id="contacts", frame_id=fmt.VIEW_SCENE_FRAME)
        entity.timestamp.FromNanoseconds(ns)
        data = entity.SerializeToString()
        if contacts is not None and len(contacts):
            count = min(len(contacts), view.DRAWN_CONTACTS_PER_STEP)
            data += arrows(contacts.point[:count], _rotations_from_x(contacts.normal[:count]),
                           self.header.radius[contacts.a[:count]], contacts.resting[:count])
        return data

    def _point_cloud(self, ns: int, positions: np.ndarray) -> bytes:
        from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField

        cloud = self.classes[fmt.TOPIC_VIEW_POINTS](frame_id=fmt.VIEW_SCENE_FRAME, point_stride=POINT_DTYPE.itemsize)
        cloud.timestamp.FromNanoseconds(ns)
        cloud.pose.orientation.w = 1.0
        kinds = {"<f8": PackedElementField.FLOAT64, "<f4": PackedElementField.FLOAT32,
                 "<u4": PackedElementField.UINT32}
        for name in POINT_DTYPE.names:
            kind, offset = POINT_DTYPE.fields[name]
            cloud.fields.add(name=name, offset=offset, type=kinds[kind.str])
        self._points["x"], self._points["y"], self._points["z"] = positions.T
        cloud.data = self._points.tobytes()
        return cloud.SerializeToString()

    def _log(self, ns: int, lines: list[tuple[str, str]]) -> list[tuple[str, bytes]]:
        out = []
        for text, level in lines:
            message = self.classes[fmt.TOPIC_VIEW_LOG](level=LOG_LEVELS[level], message=text, name="physdbg")
            message.timestamp.FromNanoseconds(ns)
            out.append((fmt.TOPIC_VIEW_LOG, message.SerializeToString()))
        return out


def _node_boxes(trees, nodes: np.ndarray, mesh: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centres (K, 3), axes (K, 3, 3) rows, half extents (K, 3)) of ``nodes`` of a mesh
    walked with an AABB or an OBB (trees: the mesh set, engine/mesh/mesh_set.MeshSet), in the mesh's frame."""
    from ..engine.mesh.tree import OBB

    if trees.volume[mesh] == OBB:
        obb = trees.node_obb[nodes]
        return obb[:, :3], obb[:, 3:12].reshape(-1, 3, 3), obb[:, 12:]
    lo, hi = trees.box_lo[nodes], trees.box_hi[nodes]
    return 0.5 * (lo + hi), np.tile(np.eye(3), (len(nodes), 1, 1)), 0.5 * (hi - lo)


def _box_edges(centres: np.ndarray, axes: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 8 corners of each oriented box (centres (K, 3), axes (K, 3, 3) rows, half extents
    (K, 3)), as (8 K, 3) points, and its 12 edges as (24 K,) indices into them, pairs of a
    line list (a third of the points of listing each edge's two ends: Foxglove's points
    are messages, built one by one)."""
    signs = np.array(list(np.ndindex(2, 2, 2)), dtype=np.float64) * 2.0 - 1.0  # (8, 3): corner b = bits (x, y, z)
    corners = centres[:, None, :] + np.einsum("bc,kc,kcd->kbd", signs, half, axes)  # (K, 8, 3)
    edges = np.array([(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]).reshape(-1)
    return corners.reshape(-1, 3), (edges[None, :] + 8 * np.arange(len(centres))[:, None]).reshape(-1)


def _rotations_from_x(directions: np.ndarray) -> np.ndarray:
    """(M, 4) unit quaternions (x, y, z, w) turning +x onto each (M, 3) unit direction
    (Foxglove's arrows point along their pose's +x)."""
    d = np.asarray(directions, dtype=np.float64)
    q = np.empty((len(d), 4))
    q[:, 0] = 0.0
    q[:, 1] = -d[:, 2]  # axis = x × d = (0, -d_z, d_y)
    q[:, 2] = d[:, 1]
    q[:, 3] = 1.0 + d[:, 0]
    opposite = q[:, 3] < 1e-9  # d = -x: a half turn about any axis normal to x
    q[opposite] = (0.0, 0.0, 1.0, 0.0)
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > 0, q / norm, np.array([0.0, 0.0, 0.0, 1.0]))
