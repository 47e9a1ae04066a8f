// chassis-foxglove against an independent implementation of the Foxglove WebSocket protocol:
// the `@foxglove/ws-protocol` client, `ws`, and `protobufjs` decoding the foxglove schemas from
// the descriptors the server advertises. A real chassisd (simulated TITAN) and the bridge run
// on loopback with their own iceoryx2 prefix and a free port. Run by scripts/foxglove-tests.
"use strict";

const test = require("node:test");
const assert = require("node:assert/strict");
const { spawn, execFileSync } = require("node:child_process");
const path = require("node:path");
const WebSocket = require("ws");
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

const BIN = process.env.CHASSIS_BIN_DIR || path.join(__dirname, "..", "..", "target", "debug");
const PREFIX = `fgt${process.pid}x${Date.now() % 100000}`;
const NAME = "fgtitan";
const env = { ...process.env, CHASSIS_IPC_PREFIX: PREFIX, RUST_LOG: process.env.RUST_LOG || "warn" };
const children = [];

function start(binary, args) {
  const child = spawn(path.join(BIN, binary), args, { env, stdio: ["ignore", "pipe", "pipe"] });
  child.output = "";
  child.stdout.on("data", (d) => (child.output += d));
  child.stderr.on("data", (d) => (child.output += d));
  children.push(child);
  return child;
}

function chassis(args) {
  return execFileSync(path.join(BIN, "chassis"), args, { env, encoding: "utf8" });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function until(what, predicate, timeoutMs = 10000) {
  const end = Date.now() + timeoutMs;
  for (;;) {
    const value = predicate();
    if (value) return value;
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await sleep(20);
  }
}

/** Starts a bridge on a free port and returns its URL once it listens. */
async function bridge(extra = [], names = NAME) {
  const child = start("chassis-foxglove", ["--name", names, "--port", "0", ...extra]);
  const match = await until("the bridge to listen", () =>
    child.output.match(/on ws:\/\/127\.0\.0\.1:(\d+)/),
  );
  return { child, url: `ws://127.0.0.1:${match[1]}` };
}

/** A connected client that records what the server says. */
async function connect(url, channels = 8) {
  const ws = new WebSocket(url, ["foxglove.sdk.v1"]);
  const client = new FoxgloveClient({ ws });
  const seen = {
    serverInfo: null,
    channels: new Map(),
    services: new Map(),
    statuses: [],
    responses: new Map(),
    failures: new Map(),
    handlers: new Map(),
  };
  client.on("serverInfo", (info) => (seen.serverInfo = info));
  client.on("advertise", (chs) => chs.forEach((c) => seen.channels.set(c.topic, c)));
  client.on("advertiseServices", (svcs) => svcs.forEach((s) => seen.services.set(s.name, s)));
  client.on("status", (s) => seen.statuses.push(s));
  client.on("message", ({ subscriptionId, data }) => {
    const handler = seen.handlers.get(subscriptionId);
    if (handler) handler(data);
  });
  client.on("serviceCallResponse", (r) => seen.responses.set(r.callId, r));
  client.on("serviceCallFailure", (f) => seen.failures.set(f.callId, f));
  await until("the server info", () => seen.serverInfo);
  await until("the channels", () => seen.channels.size >= channels);
  return { client, seen, ws };
}

function decoderFor(channel) {
  if (channel.encoding === "json") {
    return (data) => JSON.parse(Buffer.from(data.buffer, data.byteOffset, data.byteLength).toString("utf8"));
  }
  assert.equal(channel.encoding, "protobuf", channel.topic);
  assert.equal(channel.schemaEncoding, "protobuf", channel.topic);
  const set = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
  const type = protobuf.Root.fromDescriptor(set).lookupType(channel.schemaName);
  return (data) => type.toObject(type.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength)), { defaults: true, longs: Number });
}

/** Subscribes to `topic`, keeping the latest decoded message and a count. */
function follow(conn, topic) {
  const channel = conn.seen.channels.get(topic);
  assert.ok(channel, `no channel ${topic}`);
  const decode = decoderFor(channel);
  const box = { latest: null, count: 0, all: [] };
  const id = conn.client.subscribe(channel.id);
  conn.seen.handlers.set(id, (data) => {
    box.latest = decode(data);
    box.count += 1;
    if (box.all.length < 500) box.all.push(box.latest);
  });
  return box;
}

let nextCallId = 1;
async function call(conn, name, request = {}) {
  const service = conn.seen.services.get(name);
  assert.ok(service, `no service ${name}`);
  const callId = nextCallId++;
  conn.client.sendServiceCallRequest({
    serviceId: service.id,
    callId,
    encoding: "json",
    data: new Uint8Array(Buffer.from(JSON.stringify(request))),
  });
  await until(`the answer of ${name}`, () => conn.seen.responses.get(callId) || conn.seen.failures.get(callId));
  const failure = conn.seen.failures.get(callId);
  if (failure) throw new Error(`${name} failed: ${failure.message}`);
  const r = conn.seen.responses.get(callId);
  return JSON.parse(Buffer.from(r.data.buffer, r.data.byteOffset, r.data.byteLength).toString("utf8"));
}

test.after(() => {
  for (const child of children) child.kill("SIGTERM");
});

test("chassis-foxglove serves the simulated robot to a Foxglove client", async (t) => {
  const chassisd = start("chassisd", ["--robot", "titan", "--name", NAME, "--no-safety-monitor"]);
  const { url, child } = await bridge();
  const conn = await connect(url);
  t.after(() => conn.client.close());

  await t.test("the channels and their schemas are advertised", () => {
    const expected = {
      "/tf": "foxglove.FrameTransforms",
      "/pose": "foxglove.PoseInFrame",
      "/scene": "foxglove.SceneUpdate",
      "/gps": "foxglove.LocationFix",
      "/log": "foxglove.Log",
      "/state": "chassis.ChassisState",
      "/mux": "chassis.MuxStatus",
      "/safety": "chassis.SafetyStatus",
      "/frames": "chassis.Frames",
    };
    for (const [topic, schemaName] of Object.entries(expected)) {
      const channel = conn.seen.channels.get(topic);
      assert.ok(channel, `${topic} advertised`);
      assert.equal(channel.schemaName, schemaName, topic);
    }
    const state = conn.seen.channels.get("/state");
    assert.equal(state.encoding, "json");
    assert.equal(state.schemaEncoding, "jsonschema");
    const schema = JSON.parse(state.schema);
    assert.equal(schema.properties.motion.properties.linear_mps.type, "number");
    const caps = conn.seen.serverInfo.capabilities;
    assert.ok(caps.includes("clientPublish"), caps.join(","));
    assert.ok(caps.includes("services"), caps.join(","));
    assert.ok(conn.seen.serverInfo.supportedEncodings.includes("json"));
  });

  const tf = follow(conn, "/tf");
  const pose = follow(conn, "/pose");
  const state = follow(conn, "/state");
  const mux = follow(conn, "/mux");
  const log = follow(conn, "/log");
  const frames = follow(conn, "/frames");
  const scene = follow(conn, "/scene");

  await t.test("/tf, /pose and /state decode while the robot stands", async () => {
    await until("state, pose and tf", () => state.latest && pose.latest && tf.latest);
    assert.equal(pose.latest.frame_id, "odom");
    const base = tf.latest.transforms.find((x) => x.child_frame_id === "base_link");
    assert.ok(base, JSON.stringify(tf.latest));
    assert.equal(base.parent_frame_id, "odom");
    assert.equal(typeof state.latest.motion.linear_mps, "number");
    await until("a batch of decoded frames", () => frames.latest && frames.latest.frames.some((f) => f.decoded));
  });

  await t.test("services answer with chassisd's response", async () => {
    await until("services", () => conn.seen.services.has("/estop") && conn.seen.services.has("/clear_faults"));
    const names = [...conn.seen.services.keys()];
    for (const n of ["/estop", "/estop_release", "/clear_faults", "/mode", "/brake"]) {
      assert.ok(names.includes(n), names.join(","));
    }
    const mode = await call(conn, "/mode", { take_control: true });
    assert.equal(mode.ok, true, JSON.stringify(mode));
    const clear = await call(conn, "/clear_faults", { which: "all" });
    assert.equal(typeof clear.ok, "boolean");
    assert.equal(typeof clear.message, "string");
    assert.ok(clear.status.length > 0);
  });

  await t.test("a Teleop twist drives the robot as the foxglove source", async () => {
    const x0 = pose.latest.pose.position.x;
    const channelId = conn.client.advertise({
      topic: "/cmd_vel",
      encoding: "json",
      schemaName: "geometry_msgs/Twist",
    });
    const twist = new Uint8Array(
      Buffer.from(JSON.stringify({ linear: { x: 0.5, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } })),
    );
    const zero = new Uint8Array(
      Buffer.from(JSON.stringify({ linear: { x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } })),
    );
    let asking = twist;
    const timer = setInterval(() => conn.client.sendMessage(channelId, asking), 50);
    t.after(() => clearInterval(timer));
    await until("the foxglove source to win the mux", () => mux.latest && mux.latest.active_name === "foxglove");
    await until("the robot to drive", () => state.latest.motion.linear_mps > 0.2);
    await until("the pose to move forward", () => pose.latest.pose.position.x > x0 + 0.2);
    const base = tf.latest.transforms.find((x) => x.child_frame_id === "base_link");
    assert.ok(base.translation.x > x0 + 0.1, JSON.stringify(base));
    assert.ok(Math.abs(base.translation.x - pose.latest.pose.position.x) < 0.2, "tf and pose agree");
    // The scene: the body in base_link, the trail in odom behind it.
    await until("a trail in the scene", () => {
      const trail = scene.latest && scene.latest.entities.find((e) => e.id === "trail");
      return trail && trail.lines[0].points.length > 5;
    });
    const entities = Object.fromEntries(scene.latest.entities.map((e) => [e.id, e]));
    assert.equal(entities.body.frame_id, "base_link");
    assert.equal(entities.body.cubes.length, 1);
    assert.equal(entities.trail.frame_id, "odom");

    // The operator's e-stop takes the mux from it while it keeps publishing.
    chassis(["control", "--name", NAME, "estop"]);
    await until("the e-stop to take the mux", () => mux.latest.active_name !== "foxglove" && mux.latest.locks_held.includes("estop"));
    await until("the robot to stand", () => Math.abs(state.latest.motion.linear_mps) < 0.001);
    assert.ok(log.all.some((l) => /mux/.test(l.message)), JSON.stringify(log.all.map((l) => l.message)));

    // Released through the service while the Teleop still asks for 0.5 m/s: nothing moves, and
    // the mux says it waits for the foxglove source's zero.
    const release = await call(conn, "/estop_release");
    assert.equal(release.ok, true, JSON.stringify(release));
    let peak = 0;
    const end = Date.now() + 1500;
    while (Date.now() < end) {
      peak = Math.max(peak, Math.abs(state.latest.motion.linear_mps));
      await sleep(20);
    }
    assert.ok(peak < 0.01, `the release started motion: ${peak} m/s`);
    assert.match(release.message, /until foxglove asks for zero/);
    assert.equal(mux.latest.zero_reason_name, "awaiting_zero", JSON.stringify(mux.latest));
    // A zero from the Teleop, then it drives again.
    asking = zero;
    await until("the mux to take the zero", () => mux.latest.zero_reason_name !== "awaiting_zero");
    asking = twist;
    await until("the foxglove source to win again", () => mux.latest.active_name === "foxglove");
    await until("the robot to drive again", () => state.latest.motion.linear_mps > 0.2);
    clearInterval(timer);
    conn.client.unadvertise(channelId);
    await until("the robot to stop after the Teleop", () => Math.abs(state.latest.motion.linear_mps) < 0.05);
  });

  await t.test("a read-only bridge refuses client channels", async () => {
    const ro = await bridge(["--read-only"]);
    const view = await connect(ro.url);
    t.after(() => view.client.close());
    assert.ok(!view.seen.serverInfo.capabilities.includes("clientPublish"));
    await until("its services", () => view.seen.services.size > 0);
    assert.deepEqual([...view.seen.services.keys()], ["/estop"]);
    const pose = follow(view, "/pose");
    await until("a pose", () => pose.latest);
    const x0 = pose.latest.pose.position.x;
    const id = view.client.advertise({ topic: "/cmd_vel", encoding: "json", schemaName: "geometry_msgs/Twist" });
    await until("the refusal", () => view.seen.statuses.some((s) => /clientPublish/.test(s.message)));
    const twist = new Uint8Array(Buffer.from(JSON.stringify({ linear: { x: 0.5 }, angular: { z: 0 } })));
    for (let i = 0; i < 20; i++) {
      view.client.sendMessage(id, twist);
      await sleep(50);
    }
    assert.ok(Math.abs(pose.latest.pose.position.x - x0) < 0.02, "the robot did not move");
    assert.ok(mux.latest.active_name !== "foxglove");
  });

  assert.equal(chassisd.exitCode, null, chassisd.output);
  assert.equal(child.exitCode, null, child.output);
});

test("one bridge serves several robots, each under its own prefix and frames", async (t) => {
  const names = [`${NAME}a`, `${NAME}b`];
  const robots = [
    start("chassisd", ["--robot", "titan", "--name", names[0], "--no-safety-monitor"]),
    start("chassisd", ["--robot", "scout-mini", "--name", names[1], "--no-safety-monitor"]),
  ];
  const { url, child } = await bridge([], names.join(","));
  const conn = await connect(url, 16);
  t.after(() => conn.client.close());

  // Every channel and service of each robot under its name; none left unprefixed.
  for (const name of names) {
    for (const topic of ["tf", "pose", "scene", "gps", "log", "state", "mux", "frames"]) {
      assert.ok(conn.seen.channels.has(`/${name}/${topic}`), `/${name}/${topic} advertised`);
    }
  }
  assert.ok(!conn.seen.channels.has("/state"), "no unprefixed channel");
  await until("both robots' services", () => names.every((n) => conn.seen.services.has(`/${n}/estop`)));
  assert.ok(!conn.seen.services.has("/estop"), "no unprefixed service");

  const pose = names.map((n) => follow(conn, `/${n}/pose`));
  const tf = names.map((n) => follow(conn, `/${n}/tf`));
  const mux = names.map((n) => follow(conn, `/${n}/mux`));
  const scene = follow(conn, `/${names[1]}/scene`);
  const log = follow(conn, `/${names[1]}/log`);
  await until("both poses and transforms", () => pose.every((p) => p.latest) && tf.every((x) => x.latest));
  names.forEach((name, i) => {
    assert.equal(pose[i].latest.frame_id, `${name}/odom`);
    const base = tf[i].latest.transforms.find((x) => x.child_frame_id === `${name}/base_link`);
    assert.ok(base, JSON.stringify(tf[i].latest));
    assert.equal(base.parent_frame_id, `${name}/odom`);
    // Sensors hang from the robot's own base_link.
    for (const x of tf[i].latest.transforms) {
      assert.ok(x.child_frame_id.startsWith(`${name}/`), JSON.stringify(x));
    }
  });
  await until("the second robot's body", () => scene.latest && scene.latest.entities.some((e) => e.id === "body"));
  assert.ok(scene.latest.entities.every((e) => e.frame_id.startsWith(`${names[1]}/`)), JSON.stringify(scene.latest.entities.map((e) => e.frame_id)));
  await until("the second robot's description in its log", () => log.all.some((l) => /SCOUT MINI/i.test(l.message)));

  // A Teleop on the second robot's topic drives it alone.
  const x0 = pose.map((p) => p.latest.pose.position.x);
  const id = conn.client.advertise({ topic: `/${names[1]}/cmd_vel`, encoding: "json", schemaName: "geometry_msgs/Twist" });
  const twist = new Uint8Array(Buffer.from(JSON.stringify({ linear: { x: 0.4, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } })));
  const timer = setInterval(() => conn.client.sendMessage(id, twist), 50);
  t.after(() => clearInterval(timer));
  await until("the second robot to move", () => pose[1].latest.pose.position.x > x0[1] + 0.2);
  assert.equal(mux[1].latest.active_name, "foxglove");
  assert.ok(Math.abs(pose[0].latest.pose.position.x - x0[0]) < 0.01, "the first robot stood still");
  assert.notEqual(mux[0].latest.active_name, "foxglove");

  // A Teleop on a topic under no robot's name is refused with a status and drives nothing.
  const stray = conn.client.advertise({ topic: "/cmd_vel", encoding: "json", schemaName: "geometry_msgs/Twist" });
  await until("the refusal of /cmd_vel", () => conn.seen.statuses.some((s) => /names no robot/.test(s.message)));
  conn.client.unadvertise(stray);

  // The first robot's e-stop service holds the first robot only.
  const stop = await call(conn, `/${names[0]}/estop`);
  assert.equal(stop.ok, true, JSON.stringify(stop));
  await until("the first robot's e-stop", () => mux[0].latest.locks_held.includes("estop"));
  assert.ok(!mux[1].latest.locks_held.includes("estop"), JSON.stringify(mux[1].latest));
  assert.equal(mux[1].latest.active_name, "foxglove");
  clearInterval(timer);
  conn.client.unadvertise(id);

  for (const r of robots) assert.equal(r.exitCode, null, r.output);
  assert.equal(child.exitCode, null, child.output);
});
