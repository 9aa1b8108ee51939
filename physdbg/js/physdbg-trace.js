// physdbg-trace.js: record a JavaScript engine's run for `physdbg check-run`.
// No dependencies. In a page: <script src="physdbg-trace.js"></script> (or import it as a
// module) defines physdbgTrace; under Node: const physdbgTrace = require("./physdbg-trace.js").
//
//   const trace = physdbgTrace.start("bounce");          // the scene's name
//   trace.frame(t, positions, velocities);                // t in seconds: before the first step
//                                                         // (t = 0), then after every step
//   trace.finish();                                       // the browser downloads bounce.jsonl;
//                                                         // Node writes it and returns its path
//
// positions and velocities: [[x, y, z], ...] in the scene's order, or a flat array of
// 3·N numbers (a Float32Array or Float64Array as a WebGL engine keeps them); velocities
// may be left out (physdbg estimates them). The file is physdbg's JSON Lines run format
// (docs/foreign-runs.md): one {"step", "time", "positions", "velocities"} object a frame.
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

  function start(scene, options) {
    if (typeof scene !== "string" || !scene) throw new Error("physdbg-trace: start(scene): the scene's name");
    const lines = [];
    let finished = false;
    return {
      scene: scene,
      get frames() { return lines.length; },
      frame(time, positions, velocities) {
        if (finished) throw new Error("physdbg-trace: frame() after finish()");
        const step = lines.length;
        const record = { step: step, time: number(time), positions: vectors(positions, "positions", step) };
        const v = vectors(velocities, "velocities", step);
        if (v !== undefined) record.velocities = v;
        lines.push(JSON.stringify(record));
      },
      text() { return lines.join("\n") + (lines.length ? "\n" : ""); },
      finish(path) {
        finished = true;
        const name = path || (options && options.file) || `${scene}.jsonl`;
        const text = this.text();
        if (typeof document !== "undefined" && typeof Blob !== "undefined") {
          const a = document.createElement("a");
          a.href = URL.createObjectURL(new Blob([text], { type: "application/x-ndjson" }));
          a.download = name;
          document.body.appendChild(a);
          a.click();
          a.remove();
          setTimeout(() => URL.revokeObjectURL(a.href), 1000);
          return name;
        }
        const fs = typeof process !== "undefined" && process.getBuiltinModule ? process.getBuiltinModule("fs")
                 : typeof require === "function" ? require("fs") : null;
        if (!fs) throw new Error("physdbg-trace: finish(): no document to download from and no file system");
        fs.writeFileSync(name, text);
        return name;
      },
    };
  }

  return { start: start, version: 1 };
});
