// A student's engine in JavaScript, written from the seed's slides (point masses, gravity,
// drag v·d^t, Euler, swept sphere–plane and sphere–sphere tests, impulses with restitution,
// the earliest contact first and the rest of the step finished), traced with
// physdbg-trace.js. The same engine as tests/student_engine.py's swept one, done right.
//
//   node student_engine.js SCENE.json OUT.jsonl [--ms] [--mistake NAME]
//
// or in a page, after physdbg-trace.js: studentEngine.run(scene).finish() (downloads).
// SCENE.json: a physdbg scene table, as `physdbg scenes show NAME --format json` prints it
// (particles with position, velocity, radius, mass or inverse_mass, restitution; planes with
// normal, offset, restitution; gravity, drag, dt, steps). The tracer is started with that
// scene, so the run carries it and check-run needs no --scene. --mistake plants one of
// MISTAKES, as tests/student_engine.py's swept engine does (each contact once a step).
"use strict";

function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
function add(a, b, s) { return [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]; }

const MISTAKES = ["one-missing", "impulse-doubled", "restitution-sign", "tangent-reversed", "drag-per-step"];

function step(world, dt, mistake) {
  const { x, v, inv, r, e, g, walls, drag } = world;
  const n = r.length;
  const anchorT = new Array(n).fill(0), anchorX = x.map(p => p.slice()), anchorV = v.map(p => p.slice());
  const position = (i, t) => add(anchorX[i], anchorV[i], t - anchorT[i]);
  const velocity = (i, t) => {
    const tau = t - anchorT[i], d = mistake === "drag-per-step" && tau === dt ? drag : Math.pow(drag, tau);
    return [anchorV[i][0] * d + g[i][0] * tau, anchorV[i][1] * d + g[i][1] * tau, anchorV[i][2] * d + g[i][2] * tau];
  };
  function events(now) {
    const found = [];
    for (let i = 0; i < n; i++) {
      if (inv[i] === 0) continue;
      walls.normals.forEach((normal, w) => {
        const h = dot(position(i, now), normal) - walls.offsets[w] - r[i];
        const speed = dot(anchorV[i], normal);
        if (speed < 0 && h >= -1e-12) {
          const t = now + Math.max(h, 0) / -speed;
          if (t <= dt) found.push([t, 0, i, w]);
        }
      });
    }
    for (let i = 0; i < n; i++) {
      for (let j = i + 1; j < n; j++) {
        if (inv[i] + inv[j] === 0) continue;
        const pi = position(i, now), pj = position(j, now);
        const d = [pi[0] - pj[0], pi[1] - pj[1], pi[2] - pj[2]];
        const u = [anchorV[i][0] - anchorV[j][0], anchorV[i][1] - anchorV[j][1], anchorV[i][2] - anchorV[j][2]];
        const closing = dot(d, u);
        if (closing >= 0) continue;
        const a = dot(u, u), b = 2 * closing, c = dot(d, d) - (r[i] + r[j]) ** 2;
        const disc = b * b - 4 * a * c;
        if (disc < 0) continue;
        const t = now + Math.max((-b - Math.sqrt(disc)) / (2 * a), 0);
        if (t <= dt) found.push([t, 1, i, j]);
      }
    }
    return found.sort((p, q) => p[0] - q[0] || p[1] - q[1] || p[2] - q[2] || p[3] - q[3]);
  }
  function anchor(i, t, after) { anchorX[i] = position(i, t); anchorV[i] = after; anchorT[i] = t; }
  function resolve(t, kind, a, other) {
    const va = velocity(a, t);
    if (kind === 0) {
      const normal = walls.normals[other], rest = Math.min(e[a], walls.restitution[other]);
      if (mistake === "tangent-reversed") anchor(a, t, [-rest * va[0], -rest * va[1], -rest * va[2]]);
      else if (mistake === "restitution-sign") anchor(a, t, add(va, normal, -(1 - rest) * dot(va, normal)));
      else anchor(a, t, add(va, normal, -(1 + rest) * dot(va, normal)));   // R = v − (1 + e)(v·n)n
      return;
    }
    const vb = velocity(other, t), xa = position(a, t), xb = position(other, t);
    const d = [xa[0] - xb[0], xa[1] - xb[1], xa[2] - xb[2]], len = Math.sqrt(dot(d, d));
    const normal = [d[0] / len, d[1] / len, d[2] / len];
    const closing = dot([va[0] - vb[0], va[1] - vb[1], va[2] - vb[2]], normal);
    const rest = Math.min(e[a], e[other]);
    const factor = mistake === "one-missing" ? rest : mistake === "restitution-sign" ? 1 - rest : 1 + rest;
    const j = -factor * closing / (inv[a] + inv[other]) * (mistake === "impulse-doubled" ? 2 : 1);
    anchor(a, t, add(va, normal, j * inv[a]));
    anchor(other, t, add(vb, normal, -j * inv[other]));
  }
  // a mistake that leaves a pair approaching takes each contact once a step (else it would
  // meet the pair again at once, and again); the right engine needs no such guard
  const guarded = mistake === "one-missing" || mistake === "restitution-sign";
  let now = 0;
  const done = new Set();
  for (let k = 0; k < 2000; k++) {
    const ahead = events(now).filter(ev => !done.has(ev.slice(1).join(" ")));
    if (!ahead.length) break;
    const [t, kind, a, other] = ahead[0];
    now = t;
    if (guarded) done.add([kind, a, other].join(" "));
    resolve(t, kind, a, other);
  }
  for (let i = 0; i < n; i++) { x[i] = position(i, dt); v[i] = velocity(i, dt); }
}

function run(scene, options) {
  const opts = options || {};
  if (opts.mistake && !MISTAKES.includes(opts.mistake)) throw new Error(`no mistake ${opts.mistake}: ${MISTAKES}`);
  const spheres = scene.particles;
  const unit = n => { const l = Math.sqrt(dot(n, n)); return [n[0] / l, n[1] / l, n[2] / l]; };
  const planes = scene.planes || [];
  const inv = spheres.map(p => ("inverse_mass" in p ? p.inverse_mass : 1 / (p.mass === undefined ? 1 : p.mass)));
  const gravity = scene.gravity || [0, 0, 0];
  const world = {
    x: spheres.map(p => p.position.slice()), v: spheres.map(p => (p.velocity || [0, 0, 0]).slice()), inv,
    r: spheres.map(p => p.radius), e: spheres.map(p => (p.restitution === undefined ? 1 : p.restitution)),
    walls: { normals: planes.map(p => unit(p.normal)), offsets: planes.map(p => p.offset || 0),
             restitution: planes.map(p => (p.restitution === undefined ? 1 : p.restitution)) },
    drag: scene.drag === undefined ? 1 : scene.drag,
    g: spheres.map((p, i) => gravity.map(c => (inv[i] > 0 ? c * (p.gravity_scale === undefined ? 1 : p.gravity_scale) : 0))),
  };
  const trace = opts.tracer.start(scene, { file: opts.file, server: opts.server });
  trace.frame(0, world.x, world.v);
  for (let k = 1; k <= scene.steps; k++) {
    step(world, scene.dt, opts.mistake);
    const t = k * scene.dt;
    trace.frame(opts.milliseconds ? t * 1000 : t, world.x, world.v);   // milliseconds: a Date.now() clock
  }
  return trace;
}

if (typeof module === "object" && module && require.main === module) {
  const fs = require("fs");
  const path = require("path");
  const tracer = require(process.env.PHYSDBG_TRACE || path.join(__dirname, "physdbg-trace.js"));
  const [scenePath, out, ...flags] = process.argv.slice(2);
  const scene = JSON.parse(fs.readFileSync(scenePath, "utf8"));
  const mistake = flags.includes("--mistake") ? flags[flags.indexOf("--mistake") + 1] : undefined;
  console.log(run(scene, { tracer, file: out, milliseconds: flags.includes("--ms"), mistake }).finish());
} else {
  globalThis.studentEngine = { run: (scene, options) => run(scene, { tracer: globalThis.physdbgTrace, ...options }) };
}
