"""A student's engine, as the course's last exercise writes it: explicit Euler, contacts
tested where each step ends, the seed's impulse and reflection. ``flip`` gets the impulse's
sign wrong. It exports its run in physdbg's foreign-run formats (docs/foreign-runs.md)."""

from __future__ import annotations

import json

import numpy as np


def simulate(scene, steps: int, dt: float, flip: bool = False):
    """(times (F,), positions (F, N, 3), velocities (F, N, 3)) of a physdbg Scene."""
    st, walls = scene.state, scene.walls
    x, v = st.positions.copy(), st.velocities.copy()
    inv, r, e = st.inverse_mass, st.radius, st.restitution
    g = np.asarray(scene.settings.gravity)
    times, xs, vs = [0.0], [x.copy()], [v.copy()]
    for k in range(1, steps + 1):
        x = x + v * dt  # P_new = P_old + v t
        v = v + g * (inv > 0)[:, None] * dt
        for n, d, two in zip(walls.normals, walls.offsets, walls.two_sided, strict=True):
            gap = x @ n - d
            side = np.sign(gap) if two else np.ones_like(gap)
            hit = (np.abs(gap) < r) if two else (gap < r)
            for i in np.flatnonzero(hit & (inv > 0)):
                normal = side[i] * n
                if v[i] @ normal < 0:  # reflect: v - (1 + e)(v·n) n
                    v[i] = v[i] - (1 + e[i]) * (v[i] @ normal) * normal
        for a in range(len(r)):
            for b in range(a + 1, len(r)):
                delta = x[a] - x[b]
                dist = float(np.linalg.norm(delta))
                if dist < r[a] + r[b] and inv[a] + inv[b] > 0:
                    n = delta / dist
                    closing = (v[a] - v[b]) @ n
                    if closing < 0:
                        j = -(1 + min(e[a], e[b])) * closing / (inv[a] + inv[b])
                        if flip:
                            j = -j
                        v[a] += j * inv[a] * n
                        v[b] -= j * inv[b] * n
        times.append(k * dt)
        xs.append(x.copy())
        vs.append(v.copy())
    return np.array(times), np.array(xs), np.array(vs)


def write_csv(path, times, xs, vs=None) -> None:
    with open(path, "w") as f:
        f.write("step,time,body,x,y,z" + (",vx,vy,vz" if vs is not None else "") + "\n")
        for k, t in enumerate(times):
            for i, p in enumerate(xs[k]):
                row = [k, repr(float(t)), i, *map(repr, map(float, p))]
                if vs is not None:
                    row += list(map(repr, map(float, vs[k][i])))
                f.write(",".join(map(str, row)) + "\n")


def write_jsonl(path, times, xs, vs=None) -> None:
    with open(path, "w") as f:
        for k, t in enumerate(times):
            record = {"step": k, "time": float(t), "positions": xs[k].tolist()}
            if vs is not None:
                record["velocities"] = vs[k].tolist()
            f.write(json.dumps(record) + "\n")


def trace_text(scene, times, xs, vs) -> bytes:
    """A run as physdbg-trace.js writes it: the scene (its table, as `physdbg scenes show
    NAME --format json` prints it) on the first line, then a frame a line."""
    from physdbg.scene import scene_table

    lines = [json.dumps({"scene": scene_table(scene)})]
    lines += [json.dumps({"step": k, "time": float(t), "positions": xs[k].tolist(), "velocities": vs[k].tolist()})
              for k, t in enumerate(times)]
    return ("\n".join(lines) + "\n").encode()


# ----------------------------------------------------------------------------- a swept student engine
# The same course's engine done right: explicit Euler as paths (a sphere moves on the
# straight line of its velocity at the last contact, its velocity gains a·t), contacts
# found along the path (swept tests against walls and spheres) and resolved one at a time
# in time order, each sphere moved on for the rest of the step. With integrator = euler
# this is physdbg's own run to the last bits, so each mistake below is the first thing a
# check of it finds. MISTAKES: the textbook ones the course warns about.
MISTAKES = (
    "drag-per-step",      # v·d each step instead of v·d^dt: the decay depends on the frame rate
    "tangent-reversed",   # a wall reflects the whole velocity (v = -e·v), not its normal part
    "restitution-sign",   # (1 - e) where (1 + e) belongs
    "impulse-doubled",    # the impulse applied twice (once per ordered pair)
    "wrong-normal",       # the impulse along the relative velocity instead of the line of centres
    "immovable-moved",    # an immovable sphere (inverse mass 0) taken as mass 1
    "skipped-rest",       # after a bounce the sphere stays where it touched for the rest of the step
    "index-order",        # the contacts predicted at the step's start resolved in index order
    "one-missing",        # the impulse's (1 + e) written e: effective restitution e − 1
    "impulse-loop",       # the impulse's sign flipped, and no guard against meeting a pair again at once
)
# Mistakes that need the once-a-step guard (each contact resolved once a step) to end a
# step at all; a right engine has no such guard, as the seed's method has none: a pair
# that parts after an impulse meets again only when their paths cross again.
GUARDED = ("drag-per-step", "tangent-reversed", "restitution-sign", "impulse-doubled", "wrong-normal",
           "immovable-moved", "skipped-rest", "one-missing")


def simulate_swept(scene, steps: int, dt: float, mistake: str | None = None, ties: str = "first"):
    """(times (F,), positions (F, N, 3), velocities (F, N, 3)) of a physdbg Scene run by
    the swept student engine, with one of MISTAKES or none. ties: which of the contacts at
    one instant it takes first, "first" (walls, then by index, as the loops find them) or
    "last" (the last found: a right engine too, which compares with <= where the other
    compares with <)."""
    assert mistake in (None, *MISTAKES), mistake
    st, walls = scene.state, scene.walls
    x, v = st.positions.copy(), st.velocities.copy()
    inv, r, e = st.inverse_mass.copy(), st.radius, st.restitution
    if mistake == "immovable-moved":
        inv = np.where(inv > 0, inv, 1.0)
    g = np.asarray(scene.settings.gravity) * (st.inverse_mass > 0)[:, None] * st.gravity_scale[:, None]
    drag = float(scene.settings.drag)
    times, xs, vs = [0.0], [x.copy()], [v.copy()]
    for k in range(1, steps + 1):
        with np.errstate(over="ignore", invalid="ignore"):  # impulse-loop's speeds overflow, as in the engine it copies
            x, v = _swept_step(x, v, g, inv, r, e, walls, dt, mistake, drag, ties)
        times.append(k * dt)
        xs.append(x.copy())
        vs.append(v.copy())
    return np.array(times), np.array(xs), np.array(vs)


def _swept_step(x0, v0, g, inv, r, e, walls, dt, mistake, drag, ties="first"):
    n = len(r)
    anchor_t = np.zeros(n)
    anchor_x = x0.copy()
    anchor_v = v0.copy()  # the path's velocity (Euler: the velocity at the anchor)
    kicked = np.zeros(n)  # the velocity's own clock: v(t) = anchor_v·d^(t - t_a) + g·(t - t_a)
    frozen = np.zeros(n, dtype=bool)  # skipped-rest: stays where it touched

    def decay(tau):
        return drag if mistake == "drag-per-step" and tau == dt else drag ** tau

    def position(i, t):
        return anchor_x[i] if frozen[i] else anchor_x[i] + anchor_v[i] * (t - anchor_t[i])

    def velocity(i, t):
        tau = t - anchor_t[i]
        return anchor_v[i] * decay(tau) + g[i] * tau

    def events(now):
        """(time, kind, a, other) of every contact ahead, soonest first."""
        found = []
        for i in range(n):
            if inv[i] == 0 or frozen[i]:
                continue
            for w, (normal, offset) in enumerate(zip(walls.normals, walls.offsets, strict=True)):
                h = position(i, now) @ normal - offset - r[i]
                speed = anchor_v[i] @ normal
                if speed < 0 and h >= -1e-12:
                    t = now + max(h, 0.0) / -speed
                    if t <= dt:
                        found.append((t, 0, i, w))
        for i in range(n):
            for j in range(i + 1, n):
                if inv[i] + inv[j] == 0:
                    continue
                d = position(i, now) - position(j, now)
                u = (anchor_v[i] if not frozen[i] else 0 * d) - (anchor_v[j] if not frozen[j] else 0 * d)
                closing = d @ u
                if closing >= 0:
                    continue
                a, b, c = u @ u, 2 * closing, d @ d - (r[i] + r[j]) ** 2
                disc = b * b - 4 * a * c
                if disc < 0:
                    continue
                t = now + max((-b - np.sqrt(disc)) / (2 * a), 0.0)
                if t <= dt:
                    found.append((t, 1, i, j))
        if ties == "last":
            return sorted(found, key=lambda ev: (ev[0], -ev[1], -ev[2], -ev[3]))
        return sorted(found)

    def resolve(t, kind, a, other):
        va = velocity(a, t)
        if kind == 0:
            normal = walls.normals[other]
            rest = min(e[a], walls.restitution[other])  # the scene's rule: the smaller of the two
            if mistake == "tangent-reversed":
                after = -rest * va
            elif mistake == "restitution-sign":
                after = va - (1 - rest) * (va @ normal) * normal
            else:
                after = va - (1 + rest) * (va @ normal) * normal
            _anchor(a, t, after)
            return
        vb = velocity(other, t)
        xa, xb = position(a, t), position(other, t)
        normal = (xa - xb) / np.linalg.norm(xa - xb)
        if mistake == "wrong-normal":  # back along the way they came
            rel = va - vb
            normal = -rel / np.linalg.norm(rel)
        closing = (va - vb) @ normal
        rest = min(e[a], e[other])
        j = -(1 + (-rest if mistake == "restitution-sign" else rest)) * closing / (inv[a] + inv[other])
        if mistake == "one-missing":
            j = -rest * closing / (inv[a] + inv[other])
        elif mistake == "impulse-loop":
            j = -j
        times = 2 if mistake == "impulse-doubled" else 1
        _anchor(a, t, va + times * j * inv[a] * normal)
        _anchor(other, t, vb - times * j * inv[other] * normal)

    def _anchor(i, t, velocity_after):
        anchor_x[i] = position(i, t)
        anchor_v[i] = velocity_after
        anchor_t[i] = t
        if mistake == "skipped-rest":
            frozen[i] = True

    if mistake == "index-order":
        for t, kind, a, other in sorted(events(0.0), key=lambda ev: (ev[2], ev[1], ev[3])):
            resolve(t, kind, a, other)
    else:
        now, done = 0.0, set()
        for _ in range(2000):
            # a guarded mistake resolves each contact once a step (else a wrong impulse that
            # leaves the bodies approaching would be applied over and over)
            ahead = [ev for ev in events(now) if ev[1:] not in done]
            if not ahead:
                break
            now, kind, a, other = ahead[0]
            if mistake in GUARDED:
                done.add((kind, a, other))
            resolve(now, kind, a, other)
    x1 = np.array([position(i, dt) for i in range(n)])
    v1 = np.array([velocity(i, dt) for i in range(n)])
    return x1, v1


# The example runs in docs/examples/mistakes/: one mistake each, on a scene made to show it
# (with integrator = euler, so the student's Euler is the scene's own and the mistake is the
# first thing that departs). tests/test_departure.py checks the files are what this writes.
EXAMPLES = {  # mistake: (scene, overrides)
    "drag-per-step": ("docs/examples/mistakes/coast.toml", []),
    "tangent-reversed": ("docs/examples/mistakes/slide.toml", []),
    "restitution-sign": ("docs/examples/mistakes/glance.toml", []),
    "impulse-doubled": ("docs/examples/mistakes/glance.toml", []),
    "wrong-normal": ("docs/examples/mistakes/glance.toml", []),
    "immovable-moved": ("docs/examples/mistakes/post.toml", []),
    "skipped-rest": ("docs/examples/mistakes/slide.toml", []),
    "index-order": ("cradle", ["integrator=euler"]),
    "one-missing": ("docs/examples/mistakes/glance.toml", []),
    "impulse-loop": ("docs/examples/mistakes/glance.toml", []),
}


def example_run(root, mistake: str):
    """(scene, times, positions, velocities) of the example run of ``mistake``; root: the
    repository (scene paths are relative to it)."""
    from pathlib import Path

    from physdbg.api import load_scene

    name, overrides = EXAMPLES[mistake]
    scene = load_scene(str(Path(root) / name) if name.endswith(".toml") else name, overrides)
    steps = scene.steps or round(scene.duration / scene.dt)
    return (scene, *simulate_swept(scene, steps, scene.dt, mistake))


def write_blown_up(root, path) -> None:
    """docs/examples/mistakes/blown-up.jsonl: the slide scene's right run, from step 30 on
    NaN in y, written as a JavaScript engine writes NaN in JSON (JSON.stringify(NaN) is null)."""
    from pathlib import Path

    from physdbg.api import load_scene

    scene = load_scene(str(Path(root) / "docs" / "examples" / "mistakes" / "slide.toml"))
    times, xs, vs = simulate_swept(scene, scene.steps, scene.dt)
    xs[30:, 0, 1] = np.nan
    vs[30:, 0, 1] = np.nan
    with open(path, "w") as f:
        for k, t in enumerate(times):
            record = {"step": k, "time": float(t), "positions": xs[k].tolist(), "velocities": vs[k].tolist()}
            f.write(json.dumps(record).replace("NaN", "null") + "\n")


if __name__ == "__main__":  # python -m tests.student_engine: write docs/examples/mistakes/
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    for mistake in MISTAKES:
        _, times, xs, vs = example_run(root, mistake)
        write_csv(root / "docs" / "examples" / "mistakes" / f"{mistake}.csv", times, xs, vs)
    write_blown_up(root, root / "docs" / "examples" / "mistakes" / "blown-up.jsonl")
