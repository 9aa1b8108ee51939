"""What every recording starts with: the scene, its constants and its initial state.

Built from a Scene for a live recording, or read back from an MCAP file for a replay, so
the sinks (MCAP, Rerun) get the same thing either way.
"""

from __future__ import annotations

import json
import uuid
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np

from ..version import __version__
from ..engine import Walls, state_hash
from ..engine.state import RENAMED_SETTINGS, Meshes
from .format import DETAIL_LEVELS, FORMAT_NAME, FORMAT_VERSION

NULLABLE_META = ("dt", "bvh_max_nodes")  # None in meta: left out of the file (Foxglove has no null type)
DEFAULT_BVH_MAX_NODES = 4095  # a full tree of depth 11; deeper levels are left out unless asked


@dataclass
class RecordingHeader:
    """The constants of a recorded run.

    meta: the JSON object of /physdbg/scene (scene table, settings, versions, detail);
    radius, inverse_mass, restitution, gravity_scale: (N,); walls: the scene's walls;
    positions, velocities: (N, 3) initial state (frame 0); state_hash: its hash.
    """

    meta: dict
    radius: np.ndarray
    inverse_mass: np.ndarray
    restitution: np.ndarray
    gravity_scale: np.ndarray
    walls: Walls
    positions: np.ndarray
    velocities: np.ndarray
    state_hash: str

    @property
    def name(self) -> str:
        return self.meta["scene"]["name"]

    @property
    def count(self) -> int:
        return len(self.radius)

    @property
    def detail(self) -> str:
        return self.meta["detail"]

    @property
    def sleeping(self) -> bool:
        """Whether the run let spheres fall asleep (sleep_speed > 0; recordings older
        than sleeping have no such setting and did not)."""
        return float(self.meta.get("settings", {}).get("sleep_speed", 0.0) or 0.0) > 0.0

    @classmethod
    def from_scene(cls, scene, detail: str = "full",
                   bvh_max_nodes: int | None = DEFAULT_BVH_MAX_NODES) -> RecordingHeader:
        """The header of a live recording of ``scene`` (a physdbg.scene.Scene)."""
        if detail not in DETAIL_LEVELS:
            raise ValueError(f"detail must be one of {', '.join(DETAIL_LEVELS)}, not {detail!r}")
        st = scene.state
        settings = {name: getattr(scene.settings, name) for name in scene.settings.__dataclass_fields__}
        meta = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "physdbg_version": __version__,
            "numpy_version": np.__version__,
            "scene": {"name": scene.name, "description": scene.description, "source": scene.source,
                      "table": scene.raw},
            "settings": _plain(settings),
            "dt": scene.dt,
            "steps": scene.steps,
            "duration": scene.duration,
            "particles": st.count,
            "detail": detail,
            "bvh_max_nodes": bvh_max_nodes,
            # who this run is: its own id (a Rerun recording id) and a readable name
            "run_id": uuid.uuid4().hex,
            "recorded_at": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "overrides": list(getattr(scene, "overrides", ())),
        }
        json.dumps(meta)  # fail here, not mid-recording, if the scene table is not plain data
        return cls(meta, st.radius.copy(), st.inverse_mass.copy(), st.restitution.copy(),
                   st.gravity_scale.copy(), scene.walls, st.positions.copy(), st.velocities.copy(),
                   state_hash(st.positions, st.velocities))

    @property
    def run_name(self) -> str:
        """A readable name for this run: scene, the settings changed from the scene file, time."""
        parts = [self.name, *self.meta.get("overrides", []), self.meta.get("recorded_at", "")]
        return " ".join(part for part in parts if part)

    def walls_json(self) -> dict:
        """The /physdbg/walls message: one object per wall (Foxglove shows no nested arrays)."""
        w = self.walls
        return {"step": 0, "walls": [
            {"name": name, "normal": [float(x) for x in normal], "offset": float(offset),
             "restitution": float(restitution), "two_sided": bool(two_sided), "thickness": float(thickness)}
            for name, normal, offset, restitution, two_sided, thickness
            in zip(w.names, w.normals, w.offsets, w.restitution, w.two_sided, w.thickness, strict=True)],
            "period": [float(x) for x in w.period], "period_origin": [float(x) for x in w.period_origin],
            # each fixed mesh once: its triangles' corners in the world frame, flat (T·9
            # numbers; Foxglove shows no nested arrays), exact (JSON floats round-trip)
            # at run time 0; a kinematic mesh adds its motion (state.Meshes: where it is at
            # any time follows in closed form)
            "meshes": [{"name": name, "source": source, "restitution": float(e),
                        "bounding_volume": w.meshes.bounding_volume[k],
                        "corners": w.meshes.corners[w.meshes.mesh_of == k].ravel().tolist(),
                        **({"velocity": w.meshes.velocity[k].tolist(),
                            "angular_velocity": w.meshes.angular_velocity[k].tolist(),
                            "pivot": w.meshes.pivot[k].tolist()} if w.meshes.moving[k] else {})}
                       for k, (name, source, e) in enumerate(zip(w.meshes.names, w.meshes.sources,
                                                                 w.meshes.restitution, strict=True))],
            # the partners of each kind whose module declares its fields (colliders.kinds.Field),
            # one object per partner: its name and each field's value
            **({"partners": {kind: [{"name": name, **{key: np.asarray(values[row]).tolist()
                                                      for key, values in partners.fields.items()}}
                                    for row, name in enumerate(partners.names)]
                             for kind, partners in w.partners.items()}} if w.partners else {})}

    @staticmethod
    def walls_from_json(data: dict) -> Walls:
        walls = data["walls"]
        return Walls([w["name"] for w in walls], np.array([w["normal"] for w in walls], dtype=np.float64).reshape(-1, 3),
                     np.array([w["offset"] for w in walls], dtype=np.float64),
                     np.array([w["restitution"] for w in walls], dtype=np.float64),
                     np.array([w["two_sided"] for w in walls], dtype=np.bool_),
                     np.array([w["thickness"] for w in walls], dtype=np.float64),
                     np.array(data.get("period", (0.0, 0.0, 0.0)), dtype=np.float64),
                     np.array(data.get("period_origin", (0.0, 0.0, 0.0)), dtype=np.float64),
                     RecordingHeader.meshes_from_json(data.get("meshes") or []),
                     RecordingHeader.partners_from_json(data.get("partners") or {}))

    @staticmethod
    def partners_from_json(partners: dict) -> dict:
        """The partners of the kinds that declare their fields (state.Partners by kind name),
        from a /physdbg/walls message (a field the file lacks takes its default); a kind
        this physdbg does not know, or a partner without a required field, is refused."""
        from ..engine.colliders import extra_kinds
        from ..engine.state import Partners
        from ..errors import RecordingError

        declared = {name: module.FIELDS for _code, name, module in extra_kinds()}
        out = {}
        for kind, rows in partners.items():
            if kind not in declared:
                raise RecordingError(f"the recording has partners of collider kind '{kind}', which this physdbg does "
                                     f"not know (its kinds with partners of their own: "
                                     f"{', '.join(declared) or 'none'})")
            for row in rows:
                missing = [f.name for f in declared[kind] if f.name not in row and f.default is None]
                if missing or "name" not in row:
                    raise RecordingError(f"a {kind} partner of the recording has no {', '.join(missing or ['name'])} "
                                         f"(the kind's fields: name, {', '.join(f.name for f in declared[kind])})")
            out[kind] = Partners([row["name"] for row in rows],
                                 {f.name: np.array([row.get(f.name, f.default) for row in rows],
                                                   dtype=np.float64).reshape(-1, *f.shape)
                                  for f in declared[kind]})
        return out

    @staticmethod
    def meshes_from_json(meshes: list) -> Meshes:
        """The fixed meshes of a /physdbg/walls message (none in files made before meshes)."""
        if not meshes:
            return Meshes()
        corners = [np.array(m["corners"], dtype=np.float64).reshape(-1, 3, 3) for m in meshes]
        return Meshes([m["name"] for m in meshes], np.array([m["restitution"] for m in meshes], dtype=np.float64),
                      np.concatenate(corners), np.concatenate([np.full(len(c), k, dtype=np.int64)
                                                               for k, c in enumerate(corners)]),
                      [m.get("source", "") for m in meshes], [],
                      np.array([m.get("velocity", (0.0, 0.0, 0.0)) for m in meshes], dtype=np.float64),
                      np.array([m.get("angular_velocity", (0.0, 0.0, 0.0)) for m in meshes], dtype=np.float64),
                      np.array([m.get("pivot", (0.0, 0.0, 0.0)) for m in meshes], dtype=np.float64),
                      [m.get("bounding_volume", "aabb") for m in meshes])

    def scene_json(self) -> dict:
        """The /physdbg/scene message: meta with the scene table as a JSON string (a TOML
        table may hold what Foxglove's schema subset cannot: lists of lists, mixed lists)
        and no nulls (a missing key reads back as None)."""
        meta = dict(self.meta, step=0)
        meta["scene"] = dict(meta["scene"], table=json.dumps(meta["scene"]["table"]))
        return meta

    @staticmethod
    def meta_from_json(data: dict) -> dict:
        """The meta dict of a recording from its /physdbg/scene message."""
        meta = dict(data)
        meta.pop("step", None)
        scene = dict(meta["scene"])
        if isinstance(scene.get("table"), str):
            scene["table"] = json.loads(scene["table"])
        meta["scene"] = scene
        # a recording made before a setting was renamed holds the old name: read as the new
        if isinstance(scene.get("table"), dict):
            scene["table"] = {current_name(k): v for k, v in scene["table"].items()}
        if isinstance(meta.get("settings"), dict):
            meta["settings"] = {current_name(k): v for k, v in meta["settings"].items()}
        for key in NULLABLE_META:
            meta.setdefault(key, None)
        return meta


def current_name(name: str) -> str:
    """A setting's name, or a warning's code (a budget's setting name), as it is now: a
    recording made before a setting was renamed (state.RENAMED_SETTINGS) holds the old."""
    return RENAMED_SETTINGS.get(name, name)


def _plain(value):
    """Settings as JSON-ready values (tuples become lists, numpy scalars become floats)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value
