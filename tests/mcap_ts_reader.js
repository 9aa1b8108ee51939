// The TypeScript MCAP reader (@mcap/core) on physdbg recordings: every record with CRCs checked,
// by the stream reader and the indexed one. Run by tests/test_foxglove_view.py with NODE_PATH set.
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const { FileHandleReadable } = require("@mcap/nodejs");
const { loadDecompressHandlers } = require("@mcap/support");
const fs = require("fs/promises");
(async () => {
  const decompressHandlers = await loadDecompressHandlers();
  const out = {};
  for (const path of process.argv.slice(2)) {
    const stream = new McapStreamReader({ validateCrcs: true, decompressHandlers });
    stream.append(await fs.readFile(path));
    let records = 0, streamed = 0;
    for (let r; (r = stream.nextRecord()) !== undefined; ) { records++; if (r.type === "Message") streamed++; }
    if (!stream.done()) throw new Error(`${path}: the stream reader did not reach the end`);
    const fh = await fs.open(path, "r");
    const reader = await McapIndexedReader.Initialize({ readable: new FileHandleReadable(fh), decompressHandlers });
    let indexed = 0;
    for await (const _ of reader.readMessages({ validateCrcs: true })) indexed++;
    const s = reader.statistics;
    out[path] = { records, streamed, indexed, channels: reader.channelsById.size,
                  start: String(s.messageStartTime), end: String(s.messageEndTime) };
    await fh.close();
  }
  console.log(JSON.stringify(out));
})().catch((e) => { console.error(String(e && e.stack || e)); process.exit(1); });
