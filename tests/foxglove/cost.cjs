// The cost of chassis-foxglove: CPU time of the bridge (utime + stime from /proc/PID/stat) over
// SECONDS while a simulated TITAN drives from a Teleop-style client publish at 10 Hz and one
// client subscribes to every channel. Not a test: scripts/foxglove-cost runs it and prints the
// figure with the rate of every channel.
// Usage: node cost.cjs BRIDGE_BIN_DIR SERVICE_BIN_DIR [SECONDS] [PORT]
"use strict";
const { spawn, execFileSync } = require("node:child_process");
const fs = require("node:fs");
const path = require("node:path");
const WebSocket = require("ws");
const { FoxgloveClient } = require("@foxglove/ws-protocol");

const bin = process.argv[2];
const serviceBin = process.argv[3];
const seconds = Number(process.argv[4] || 20);
const port = Number(process.argv[5] || 18765);
const env = { ...process.env, CHASSIS_IPC_PREFIX: `fgcost${process.pid}` };
const hz = Number(execFileSync("getconf", ["CLK_TCK"], { encoding: "utf8" }));
const service = spawn(path.join(serviceBin, "chassisd"), ["--robot", "titan", "--name", "cost", "--no-safety-monitor"], { env, stdio: "ignore" });
const bridge = spawn(path.join(bin, "chassis-foxglove"), ["--name", "cost", "--port", String(port)], { env, stdio: ["ignore", "ignore", "inherit"] });
const ticks = (pid) => {
  const fields = fs.readFileSync(`/proc/${pid}/stat`, "utf8").split(") ")[1].split(" ");
  return Number(fields[11]) + Number(fields[12]);
};
const stop = (code) => {
  bridge.kill("SIGTERM");
  service.kill("SIGTERM");
  process.exit(code);
};
setTimeout(() => {
  const client = new FoxgloveClient({ ws: new WebSocket(`ws://127.0.0.1:${port}`, ["foxglove.sdk.v1"]) });
  const topics = new Map();
  const counts = {};
  client.on("error", (e) => { console.error(e.message); stop(1); });
  client.on("advertise", (channels) => channels.forEach((c) => topics.set(client.subscribe(c.id), c.topic)));
  client.on("message", ({ subscriptionId }) => {
    const topic = topics.get(subscriptionId);
    counts[topic] = (counts[topic] || 0) + 1;
  });
  setTimeout(() => {
    const id = client.advertise({ topic: "/cmd_vel", encoding: "json", schemaName: "geometry_msgs/Twist" });
    let i = 0;
    setInterval(() => {
      i += 1;
      const twist = { linear: { x: 0.5, y: 0, z: 0 }, angular: { x: 0, y: 0, z: Math.sin(i / 20) } };
      client.sendMessage(id, new Uint8Array(Buffer.from(JSON.stringify(twist))));
    }, 100);
    setTimeout(() => {
      for (const k of Object.keys(counts)) counts[k] = 0;
      const t0 = ticks(bridge.pid);
      const start = Date.now();
      setTimeout(() => {
        const cpu = (ticks(bridge.pid) - t0) / hz;
        const secs = (Date.now() - start) / 1000;
        console.log(`chassis-foxglove: ${((cpu / secs) * 100).toFixed(2)} % of a core over ${secs.toFixed(1)} s`);
        for (const [topic, n] of Object.entries(counts).sort()) console.log(`  ${topic} ${(n / secs).toFixed(1)} msg/s`);
        stop(0);
      }, seconds * 1000);
    }, 2000);
  }, 500);
}, 1500);
