// physdbg-trace.js: record a JavaScript engine's run for `physdbg check-run`.
// No dependencies. In a page: <script src="physdbg-trace.js"></script> (or import it as a
// module) defines physdbgTrace; under Node: const physdbgTrace = require("./physdbg-trace.js").
//
//   const trace = physdbgTrace.start(scene);             // the scene: a built-in's name ("bounce"),
//                                                         // or the scene object the engine runs
//   trace.frame(t, positions, velocities);                // t in seconds: before the first step
//                                                         // (t = 0), then after every step
//   trace.finish();                                       // a page: sends the run to `physdbg check-run
//                                                         // --serve` and shows its verdict (a Promise of
//                                                         // it), or downloads bounce.jsonl when no server
//                                                         // answers; Node writes it and returns its path
//   start(scene, {server: "http://127.0.0.1:8765"})       // the server (false: always download)
//
// positions and velocities: [[x, y, z], ...] in the scene's order, or a flat array of
// 3·N numbers (a Float32Array or Float64Array as a WebGL engine keeps them); velocities
// may be left out (physdbg estimates them). The file is physdbg's JSON Lines run format
// (docs/foreign-runs.md): its first line {"scene": ...} carries the scene (so check-run needs
// no --scene), then one {"step", "time", "positions", "velocities"} object a frame. A scene
// object is physdbg's scene table as JSON (`physdbg scenes show bounce --format js` prints
// one): dt, gravity, drag, integrator, particles [{position, velocity, radius, mass (or
// inverse_mass: 0, immovable), restitution}], planes [{name, normal, offset, restitution}].
// JSON has no NaN or Infinity (JSON.stringify writes null for both), so the tracer writes
// them as the strings "NaN", "Infinity" and "-Infinity", which check-run reads as what they
// were: an engine that blew up is worth explaining.
(function (root, factory) {
  const api = factory();
  if (typeof module === "object" && module && module.exports) module.exports = api;
  root.physdbgTrace = api;
})(typeof globalThis !== "undefined" ? globalThis : this, function () {
  "use strict";

  function number(x) {
    if (Number.isFinite(x)) return x;
    if (Number.isNaN(x)) return "NaN";
    if (x === Infinity) return "Infinity";
    if (x === -Infinity) return "-Infinity";
    return "NaN"; // not a number at all (undefined, a string): check-run names it non-finite
  }

  function vectors(values, what, step) {
    if (values == null) return undefined;
    const out = [];
    if (Array.isArray(values) && values.length && Array.isArray(values[0])) {
      for (const v of values) out.push([number(v[0]), number(v[1]), number(v[2])]);
    } else if (values.length % 3 === 0) {
      for (let i = 0; i < values.length; i += 3) {
        out.push([number(values[i]), number(values[i + 1]), number(values[i + 2])]);
      }
    } else {
      throw new Error(`physdbg-trace: frame ${step}: ${what} is neither [[x, y, z], ...] nor 3·N numbers ` +
                      `(${values.length} numbers)`);
    }
    return out;
  }

  const SERVER = "http://127.0.0.1:8765";   // where `physdbg check-run --serve` listens by default

  function download(file, text) {
    const a = document.createElement("a");
    a.href = URL.createObjectURL(new Blob([text], { type: "application/x-ndjson" }));
    a.download = file;
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 1000);
  }

  // The verdict in the page: a small panel (id "physdbg-verdict", its verdict in
  // data-verdict: SAME, DEPARTS or ERROR), one per page, replaced by the next run's.
  function panel(verdict, server) {
    let box = document.getElementById("physdbg-verdict");
    if (!box) {
      box = document.createElement("div");
      box.id = "physdbg-verdict";
      box.style.cssText = "position:fixed;right:12px;bottom:12px;max-width:34em;padding:10px 14px;z-index:2147483647;" +
        "font:13px/1.4 system-ui,sans-serif;background:#fff;color:#111;border-radius:6px;" +
        "box-shadow:0 2px 10px rgba(0,0,0,.3);border-left:6px solid";
      document.body.appendChild(box);
    }
    const v = verdict && verdict.verdict ? verdict.verdict : "ERROR";
    box.dataset.verdict = v;
    box.style.borderLeftColor = v === "SAME" ? "#2a9d3a" : v === "DEPARTS" ? "#d1495b" : "#999";
    box.textContent = "";
    const add = (tag, text) => { const e = document.createElement(tag); e.textContent = text; box.appendChild(e); return e; };
    add("strong", `physdbg: ${v}`).className = "physdbg-verdict-head";
    if (v === "DEPARTS") {
      add("div", `step ${verdict.step}, sphere ${verdict.body}: ${verdict.cause_words} (${verdict.cause})`)
        .className = "physdbg-verdict-where";
      add("div", verdict.finding || verdict.summary).className = "physdbg-verdict-summary";
      if (verdict.advice) add("div", `what to do: ${verdict.advice}`).className = "physdbg-verdict-advice";
      if (verdict.view) {
        const a = add("a", "open your run against physdbg's in Rerun");
        a.href = verdict.view;
        a.target = "_blank";
        a.className = "physdbg-verdict-view";
      }
    } else {
      add("div", verdict && (verdict.summary || verdict.error) || String(verdict)).className = "physdbg-verdict-summary";
    }
  }

  function start(scene, options) {
    const named = typeof scene === "string" && scene;
    if (!named && (scene === null || typeof scene !== "object" || Array.isArray(scene))) {
      throw new Error("physdbg-trace: start(scene): the scene's name (\"bounce\") or the scene object " +
                      "(physdbg scenes show NAME --format js prints one)");
    }
    const name = named ? scene : String(scene.name || "run");
    const head = JSON.stringify({ scene: scene });    // the run's first line: its scene
    const lines = [];
    let finished = false;
    return {
      scene: name,
      get frames() { return lines.length; },
      frame(time, positions, velocities) {
        if (finished) throw new Error("physdbg-trace: frame() after finish()");
        const step = lines.length;
        const record = { step: step, time: number(time), positions: vectors(positions, "positions", step) };
        const v = vectors(velocities, "velocities", step);
        if (v !== undefined) record.velocities = v;
        lines.push(JSON.stringify(record));
      },
      text() { return [head, ...lines].join("\n") + "\n"; },
      finish(path) {
        finished = true;
        const file = path || (options && options.file) || `${name}.jsonl`;
        const text = this.text();
        if (typeof document !== "undefined" && typeof Blob !== "undefined") {
          const server = options && options.server !== undefined ? options.server : SERVER;
          if (!server || typeof fetch !== "function") {
            download(file, text);
            return Promise.resolve({ downloaded: file });
          }
          // a `physdbg check-run --serve` on this machine checks the run and answers its
          // verdict, shown in a panel; with none there, the run is downloaded as before
          return fetch(`${server}/check`, { method: "POST", body: text,
                                            headers: { "Content-Type": "text/plain", "X-Physdbg-File": file } })
            .then(answer => answer.json())
            .then(verdict => { panel(verdict, server); return verdict; },
                  () => { download(file, text); return { downloaded: file }; });
        }
        const fs = typeof process !== "undefined" && process.getBuiltinModule ? process.getBuiltinModule("fs")
                 : typeof require === "function" ? require("fs") : null;
        if (!fs) throw new Error("physdbg-trace: finish(): no document to download from and no file system");
        fs.writeFileSync(file, text);
        return file;
      },
    };
  }

  return { start: start, version: 2 };
});
