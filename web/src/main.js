// riderlive previs page: wires the link (websocket), the rigs, the 3D view, the plots,
// the status lines and the controls. Page state for tests and the curious: window.riderlive.
// New panels: see panels.js (one module per panel, one line here).

import { api, attempt, bindEstop, Controls, controlToken } from "./controls.js";
import { LatencyPanel } from "./latency.js";
import { RiderLink } from "./link.js";
import { HorseNow } from "./horsenow.js";
import { emit, on } from "./panels.js";
import { PlatformView } from "./platform.js";
import { Plots } from "./plots.js";
import { FitPanel } from "./fit.js";
import { DEFAULTS, initial as initialResolution, next as nextResolution, pin as pinResolution, scaleOf } from "./resolution.js";
import { compileRig, solve } from "./rig.js";
import { SaddlePanel } from "./saddle.js";
import { chainPoints, DEFAULT_VIEW, placed, View, VIEWS, WRAP } from "./scene.js";
import { Status } from "./status.js";
import { Takes } from "./takes.js";

const $ = (id) => document.getElementById(id);
const DEFAULT_PLOTS = ["lower_back.rz", "cog.ty", "head.rz", "lfHoof.ty"];
const METRE_SCALE = 25; // thesis rig units per metre: the service speaks metres at this length_scale
const QUERY = new URLSearchParams(location.search);
const RENDER = QUERY.get("render") === "sticks" ? "sticks" : "mesh";
/** `?maxfps=N`: draw the 3D view and the plots at most N times a second (a page on the service's
 * own busy host, a wall display, a test that reads state rather than pixels); the pose, values,
 * timecode and panels still follow every frame. Absent or not a positive number: every frame. */
const MAX_FPS = ((n) => (Number.isFinite(n) && n > 0 ? n : null))(Number(QUERY.get("maxfps")));

const page = {
  connected: false,
  state: "connecting",
  session: null,
  frames: 0,
  seq: null,
  fps: 0,
  frameRate: 0,
  values: {},
  pose: { rider: {}, horse: {} },
  service: null,
  errors: [],
  render: RENDER,
  maxFps: MAX_FPS,
  draws: 0, // frames drawn (3D view), of `frames` received
  exaggeration: 1,
};
window.riderlive = page;

function groupChain(names, prefix) {
  const groups = new Map();
  for (const n of names) {
    const m = n.match(new RegExp(`^${prefix}_(\\d+)\\.`));
    if (!m) continue;
    if (!groups.has(m[1])) groups.set(m[1], []);
    groups.get(m[1]).push(n);
  }
  return [...groups.keys()].sort().map((k) => groups.get(k));
}

/** The 3D view, or null with a message saying why (no WebGL 2: the plots and controls still work). */
function makeView(skeletons) {
  try {
    const view = new View($("scene"), compileRig(skeletons.horse), compileRig(skeletons.rider), { render: RENDER });  // the bodies need only the bones
    page.view3d = true;
    return view;
  } catch (err) {
    page.view3d = false;
    $("no3d").hidden = false;
    $("no3d").textContent = `No 3D view: this browser gives no WebGL 2 (${err.message || err}). Plots, status and controls work.`;
    return null;
  }
}

/** Rider values drawn `k` times further from the rig's rest (display only). */
function exaggerated(values, rig, names, k) {
  if (k === 1) return values;
  const out = { ...values };
  for (const n of names) if (n in out && n in rig.neutral) out[n] = rig.neutral[n] + k * (out[n] - rig.neutral[n]);
  return out;
}

async function start() {
  const plots = new Plots($("plot"), $("plot-axis"));
  const controls = new Controls(page);
  const status = new Status(page, api, attempt);
  page.status = status;
  const horseNow = new HorseNow($("horse-now"));
  page.horseNow = horseNow;
  const takes = new Takes(api, attempt, (name) => controls.applySource(name), () => page.tickRate || 120);
  controls.takes = takes;
  takes.fit = new FitPanel(api, attempt, () => { takes.shown = null; return takes.refresh(); });
  page.fit = takes.fit;
  controls.onState = (state) => status.fromState(state);
  page.history = (name, seconds) => plots.recent(name, seconds);
  page.plots = plots;

  // Skeletons: the hello's (the service poses with them); /skeletons.json until it comes.
  let skeletons = await (await fetch("skeletons.json")).json();
  // The rider parts (hands on the reins, feet in the stirrups) pose with the `rider_tack`
  // rig when the service publishes them; without them the rider rig is Appendix B's limbs.
  let withParts = false;
  const riderOf = (sk) => compileRig(withParts && sk.rider_tack ? sk.rider_tack : sk.rider);
  let horseRig = compileRig(skeletons.horse);
  let riderRig = riderOf(skeletons);
  let view = makeView(skeletons);
  const useSkeletons = (sk, parts) => {
    if (!sk || !sk.rider || !sk.horse) return;
    if (parts !== withParts) {
      withParts = parts;
      riderRig = riderOf(JSON.stringify(sk) === JSON.stringify(skeletons) ? skeletons : sk);
    }
    if (JSON.stringify(sk) === JSON.stringify(skeletons)) return;
    skeletons = sk;
    horseRig = compileRig(sk.horse);
    riderRig = riderOf(sk);
    if (view) view.dispose();
    const canvas = $("scene").cloneNode(false);
    $("scene").replaceWith(canvas);
    view = makeView(sk);
    if (view) view.setView(page.viewName || DEFAULT_VIEW);
    if (view) view.setScale(page.renderScale || 1);
    if (view && page.platform) view.scene.add(page.platform.group);
  };
  page.solveRider = (values) => solve(riderRig, values).localRotations.flat();
  const saddle = new SaddlePanel($("panel"), page);
  const platform = new PlatformView(view ? view.scene : { add() {} }, $("panel"), controlToken());
  page.platform = platform;
  Object.defineProperty(page, "riderRigName", { get: () => (withParts && skeletons.rider_tack ? "rider_tack" : "rider") });

  // View controls.
  for (const [name, v] of Object.entries(VIEWS)) {
    const b = document.createElement("button");
    b.dataset.view = name;
    b.textContent = v.label;
    b.addEventListener("click", () => page.setView(name));
    $("view-buttons").appendChild(b);
  }
  page.setView = (name) => {
    page.viewName = name;
    if (view) view.setView(name);
    for (const b of document.querySelectorAll("[data-view]")) b.classList.toggle("on", b.dataset.view === name);
  };
  page.setView(DEFAULT_VIEW);
  Object.defineProperty(page, "view", { get: () => view }); // the View (diagnostics: bench/trace_page.py)
  Object.defineProperty(page, "camera", { get: () => (view ? view.camera.position.toArray() : null) });
  $("camera").addEventListener("change", () => view && view.setFollow($("camera").value === "follow"));
  $("exaggeration").addEventListener("input", () => {
    page.exaggeration = +$("exaggeration").value;
    $("exaggeration-out").textContent = page.exaggeration.toFixed(1);
  });
  page.setIdColors = (onOff) => view && view.setIdColors(onOff);
  page.project = (p) => (view ? view.project(p) : null);

  // Plots.
  const chips = () => {
    $("plot-chips").innerHTML = "";
    for (const n of plots.chosen) {
      const c = document.createElement("span");
      c.className = "chip";
      c.style.color = plots.color(n);
      c.textContent = `${n} ×`;
      c.title = "remove";
      c.addEventListener("click", () => {
        plots.chosen = plots.chosen.filter((x) => x !== n);
        chips();
      });
      $("plot-chips").appendChild(c);
    }
  };
  $("plot-add").addEventListener("change", () => {
    const n = $("plot-add").value;
    if (n && !plots.chosen.includes(n)) plots.chosen.push(n);
    $("plot-add").value = "";
    chips();
  });
  $("plot-window").addEventListener("change", () => (plots.window = +$("plot-window").value));
  $("plot-own").addEventListener("change", () => (plots.ownScale = $("plot-own").checked));

  let chains = { tail: [], braid: [], lfCloth: [], rtCloth: [] };
  let toMetres = 1;
  let lengthChannels = [];
  let riderNames = [];
  let latest = null;
  let frameCount = 0;

  const link = new RiderLink(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws/rider`, {
    hello(msg) {
      page.session = msg.session;
      useSkeletons(msg.skeletons, (msg.rider_part_channels || []).length > 0);
      // The skeletons are in metres; a service with another length_scale speaks other units.
      toMetres = (msg.length_scale || METRE_SCALE) / METRE_SCALE;
      saddle.hello(toMetres);
      const channels = [...(msg.channels || []), ...(msg.rider_part_channels || []), ...(msg.horse_channels || [])];
      lengthChannels = channels.filter((c) => c.unit === "length").map((c) => c.name);
      const unitOf = { length: msg.length_unit || "m", deg: "°" };
      for (const c of channels) plots.units[c.name] = unitOf[c.unit] ?? (c.unit === "unitless" ? "" : c.unit || "");
      riderNames = [...(msg.channels || []), ...(msg.rider_part_channels || [])].map((c) => c.name);
      page.tickRate = msg.tick_rate;
      const all = [...new Set(channels.map((c) => c.name))];
      chains = {
        tail: groupChain(all, "tail"),
        braid: groupChain(all, "braid"),
        lfCloth: groupChain(all, "lf_cloth"),
        rtCloth: groupChain(all, "rt_cloth"),
      };
      $("plot-add").innerHTML = `<option value="">add a channel…</option>${all.map((n) => `<option>${n}</option>`).join("")}`;
      if (plots.chosen.length === 0) plots.chosen = DEFAULT_PLOTS.filter((n) => all.includes(n));
      chips();
      controls.load(msg.channels || []);
      status.fetchDevices();
      emit("hello", msg);
    },
    frame(frame) {
      latest = frame;
      pinMatches(frame);
      frameCount += 1;
      page.frames += 1;
      page.seq = frame.seq;
      if (frame.driver !== page.driver) {
        page.driver = frame.driver;
        status.show();
      }
      plots.push(frame.t, frame.values);
      const root = { "root.tx": frame.values["root.tx"] * toMetres, "root.tz": frame.values["root.tz"] * toMetres };
      horseNow.frame(frame.t, root, frame.driver);
      saddle.frame(frame);
      emit("frame", frame);
    },
    status(msg) {
      page.tickStatus = msg;
      status.fromStatus(msg);
      horseNow.fromStatus(msg);
      controls.servos(msg.rig || null);
      platform.status(msg);
      emit("status", msg);
    },
    state(state, why) {
      page.state = state;
      page.connected = state === "live";
      const pill = $("conn");
      pill.className = `pill ${state}`;
      pill.dataset.state = state;
      pill.textContent = state === "live" ? "connected" : state === "gone" ? "service gone" : "connecting…";
      $("gone").hidden = state !== "gone";
      $("gone-why").textContent = why || "no connection";
      emit("state", state);
    },
  }, 120, controlToken());
  link.subscription = { ...SaddlePanel.subscription(), timecode: true }; // frames carry `tc` (docs/timecode.md)
  page.link = link;
  setInterval(() => controls.refresh(), 1000);
  setInterval(() => (page.horseText = horseNow.show()), 250);
  const latency = new LatencyPanel($("panel"), $("message"));
  page.latency = latency;
  setInterval(() => latency.refresh(), 1000);

  // Dynamic resolution (resolution.js): the render scale that holds 55 fps, stepping down
  // after 2 s below it and up after seconds well above it, with backoff; pinned by
  // setRenderScale(scale), automatic again with setRenderScale(null).
  let resolution = initialResolution();
  const showScale = () => {
    page.renderScale = scaleOf(resolution);
    page.renderScaleAuto = resolution.pinned === null;
    if (view) view.setScale(page.renderScale);
    $("resolution").textContent = view ? `render ${page.renderScale.toFixed(2)}× ${page.renderScaleAuto ? "auto" : "pinned"}` : "";
  };
  page.setRenderScale = (scale) => {
    resolution = pinResolution(resolution, scale);
    showScale();
  };
  Object.defineProperty(page, "resolution", { get: () => ({ ...resolution }) }); // the controller's state (diagnostics)
  page.resolutionUnit = { DEFAULTS, initial: initialResolution, next: nextResolution, pin: pinResolution, scaleOf }; // tests
  showScale();
  function adaptScale() {
    if (!view) return;
    const before = scaleOf(resolution);
    resolution = nextResolution(resolution, page.fps);
    if (scaleOf(resolution) !== before) showScale();
  }

  /** Pose both skeletons for `values` and, when `render`, draw them. */
  function drawFrame(values, render) {
    let v = values;
    if (toMetres !== 1) {
      v = { ...values };
      for (const n of lengthChannels) if (n in v) v[n] *= toMetres;
    }
    const follow = !view || view.follow;
    // Following: the horse stays at the origin, the ground scrolls. Fixed: the horse
    // travels, coming round every WRAP metres.
    const tx = v["root.tx"] || 0;
    const tz = v["root.tz"] || 0;
    const shift = follow ? [tx, tz] : [tx - (((tx % WRAP) + WRAP) % WRAP) + WRAP / 2, tz - (((tz % WRAP) + WRAP) % WRAP) + WRAP / 2];
    const hv = { ...v, "root.tx": tx - shift[0], "root.tz": tz - shift[1] };
    const horsePose = solve(horseRig, hv);
    const truth = solve(riderRig, v);
    const riderPose = page.exaggeration === 1 ? truth : solve(riderRig, exaggerated(v, riderRig, riderNames, page.exaggeration));
    const horseW = placed(horsePose, [0, 0, 0, 1], [0, 0, 0]);
    const si = horseRig.index.saddle;
    const riderW = placed(riderPose, horseW.rotations[si], horseW.positions[si]);
    const byName = (rig, list) => Object.fromEntries(rig.bones.map((b, i) => [b.name, list[i]]));
    page.pose = {
      // Built when read (tests, the console), not every animation frame; `rider` is the published pose.
      get rider() {
        return byName(riderRig, truth.localRotations);
      },
      get horse() {
        return byName(horseRig, horsePose.localRotations);
      },
      get riderWorld() {
        return byName(riderRig, riderW.positions);
      },
      get horseWorld() {
        return byName(horseRig, horseW.positions);
      },
    };
    if (!view || !render) return;
    // Chain positions (tail_NN.t*, braid_NN.t*, *_cloth_NN.t*) are world positions: shifted as the horse is.
    const toView = (p) => [p[0] - shift[0], p[1], p[2] - shift[1]];
    const ti = horseRig.index.tailRoot;
    const tailPts = ti === undefined ? null : chainPoints(v, chains.tail, horseW.positions[ti], horseW.rotations[ti], toView);
    const hi = riderRig.index.head;
    const braidPts = hi === undefined ? null : chainPoints(v, chains.braid, riderW.positions[hi], riderW.rotations[hi], toView);
    // The coat-skirt flaps start at their own first bone (at the side of the rider's hips).
    const pi = riderRig.index.hips;
    const flap = (names) => {
      const pts = pi === undefined ? null : chainPoints(v, names, riderW.positions[pi], riderW.rotations[pi], toView);
      return pts && pts.slice(1);
    };
    const clothPts = [flap(chains.lfCloth), flap(chains.rtCloth)].filter((p) => p && p.length > 1);
    view.draw({
      horse: { pose: horsePose, world: horseW },
      rider: { pose: riderPose, world: riderW },
      tail: tailPts && { values: v, groups: chains.tail, points: tailPts },
      braid: braidPts && { points: braidPts },
      cloth: clothPts.length ? clothPts : null,
      travel: follow ? tx : 0,
    });
    page.tack = view.tackUsed;
    page.clothFlaps = clothPts.length; // cloth flaps drawn (0 without the physics)
    page.tackBones = view.tack ? view.tack.uses : null;
  }

  // The 3D view as drawn, with the pose it shows (tests): taken right after the next render.
  const snapshots = [];
  page.snapshot = () => new Promise((resolve) => snapshots.push(resolve));
  // The view of the first frame received whose values match `test` (values -> bool): each
  // matching frame is queued and drawn in turn before newer ones, so a pose that lasts a
  // few ticks is caught however slowly the page draws. Rejects after `timeoutMs`.
  const pinRequests = [];
  const pinned = [];
  page.snapshotWhen = (test, timeoutMs = 10000) =>
    new Promise((resolve, reject) => {
      const request = { test, resolve };
      pinRequests.push(request);
      setTimeout(() => {
        const i = pinRequests.indexOf(request);
        if (i < 0) return;
        pinRequests.splice(i, 1);
        reject(new Error(`no frame matched within ${timeoutMs} ms: ${test}`));
      }, timeoutMs);
    });
  function pinMatches(frame) {
    for (let i = 0; i < pinRequests.length; ) {
      if (pinRequests[i].test(frame.values)) pinned.push({ frame, resolve: pinRequests.splice(i, 1)[0].resolve });
      else i += 1;
    }
  }
  function takeSnapshots() {
    if (!snapshots.length || !view) return;
    const shot = { image: view.canvas.toDataURL("image/png"), width: view.canvas.width, scale: view.canvas.width / view.canvas.clientWidth };
    shot.riderWorld = page.pose.riderWorld;
    shot.horseWorld = page.pose.horseWorld;
    shot.values = page.values;
    for (const resolve of snapshots.splice(0)) resolve(shot);
  }

  let rafCount = 0;
  let lastSecond = performance.now();
  let lastLatest = null;
  let lastPlot = 0;
  let lastDraw = -Infinity;
  let undrawn = false; // a frame posed but not drawn yet (?maxfps)
  const drawGap = MAX_FPS === null ? 0 : 1000 / MAX_FPS;
  function tick(now) {
    const t0 = performance.now();
    rafCount += 1;
    if (now - lastSecond >= 1000) {
      page.fps = (rafCount * 1000) / (now - lastSecond);
      page.frameRate = (frameCount * 1000) / (now - lastSecond);
      rafCount = 0;
      frameCount = 0;
      lastSecond = now;
      adaptScale();
      $("rates").textContent = `${page.frameRate.toFixed(0)} frames/s in · ${page.fps.toFixed(0)} fps${MAX_FPS === null ? "" : ` (drawn ≤ ${MAX_FPS}/s)`}${page.tickRate ? ` · tick ${page.tickRate} Hz` : ""}${link.restarts ? ` · service restarted ×${link.restarts}` : ""}`;
    }
    if (latest && latest.tc !== undefined && latest.tc !== page.timecode) {
      page.timecode = latest.tc;
      $("timecode").textContent = `TC ${latest.tc}`;
    }
    try {
      const pin = pinned.shift(); // a frame asked for by snapshotWhen: drawn now, whatever ?maxfps says
      if (pin) snapshots.push(pin.resolve);
      const shown = pin ? pin.frame : latest;
      const due = Boolean(pin) || now - lastDraw >= drawGap;
      const fresh = shown && (shown !== lastLatest || page.exaggeration !== 1 || Boolean(pin));
      if (fresh) {
        lastLatest = shown;
        page.values = shown.values;
        undrawn = true;
      }
      if (shown && undrawn && (fresh || due)) {
        drawFrame(shown.values, due); // posed on every frame, drawn when due
        if (due) {
          undrawn = false;
          lastDraw = now;
          page.draws += 1;
          takeSnapshots();
        }
      } else if (!shown && due) {
        drawFrame({}, true);
        lastDraw = now;
      }
    } catch (err) {
      page.errors.push(String(err));
      throw err;
    }
    if (now - lastPlot >= Math.max(33, drawGap)) {
      lastPlot = now; // plots at <= 30 Hz: enough for the eye, half the canvas work
      plots.draw();
    }
    page.tickMs = 0.95 * (page.tickMs || 0) + 0.05 * (performance.now() - t0); // JS time per animation frame
    requestAnimationFrame(tick);
  }
  requestAnimationFrame(tick);
}

bindEstop(() => page.status && page.status.fetchDevices());
window.addEventListener("error", (ev) => page.errors.push(String(ev.message)));
page.on = on;
start().catch((err) => {
  page.errors.push(String(err));
  $("message").textContent = `page failed to start: ${err}`;
});
