// riderlive previs page: wires the link (websocket), the rigs, the 3D view, the plots
// and the controls. Page state for tests and the curious: window.riderlive.

import { bindEstop, Controls, controlToken } from "./controls.js";
import { RiderLink } from "./link.js";
import { PlatformView } from "./platform.js";
import { Plots } from "./plots.js";
import { compileRig, solve } from "./rig.js";
import { SaddlePanel } from "./saddle.js";
import { chainPoints, placed, View } from "./scene.js";

const $ = (id) => document.getElementById(id);
const DEFAULT_PLOTS = ["lower_back.rz", "cog.ty", "head.rz", "lfHoof.ty"];
const METRE_SCALE = 25; // thesis rig units per metre: the service speaks metres at this length_scale

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

async function start() {
  const skeletons = await (await fetch("skeletons.json")).json();
  // Served by the same service as the frames, so always the skeletons it poses with.
  const horseRig = compileRig(skeletons.horse);
  const riderRig = compileRig(skeletons.rider);
  const view = new View($("scene"), horseRig, riderRig);
  const plots = new Plots($("plot"));
  const controls = new Controls(page);
  const saddle = new SaddlePanel($("panel"), page);
  const platform = new PlatformView(view.scene, $("panel"), controlToken());
  page.platform = platform;
  page.solveRider = (values) => solve(riderRig, values).localRotations.flat();
  page.setView = (name) => view.setView(name);
  page.history = (name, seconds) => plots.recent(name, seconds);
  Object.defineProperty(page, "camera", { get: () => view.camera.position.toArray() });
  for (const b of document.querySelectorAll("[data-view]")) b.addEventListener("click", () => view.setView(b.dataset.view));

  let chains = { tail: [], braid: [] };
  let toMetres = 1;
  let lengthChannels = [];
  let latest = null;
  let frameCount = 0;
  const chips = () => {
    $("plot-chips").innerHTML = plots.chosen
      .map((n) => `<span class="chip" style="color:${plots.color(n)}" data-name="${n}" title="remove">${n} ×</span>`)
      .join("");
    for (const c of $("plot-chips").children)
      c.addEventListener("click", () => {
        plots.chosen = plots.chosen.filter((n) => n !== c.dataset.name);
        chips();
      });
  };
  $("plot-add").addEventListener("change", () => {
    const n = $("plot-add").value;
    if (n && !plots.chosen.includes(n)) plots.chosen.push(n);
    $("plot-add").value = "";
    chips();
  });

  const link = new RiderLink(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws/rider`, {
    hello(msg) {
      page.session = msg.session;
      // The skeletons are in metres; a service with another length_scale speaks other units.
      toMetres = (msg.length_scale || METRE_SCALE) / METRE_SCALE;
      saddle.hello(toMetres);
      lengthChannels = [...(msg.channels || []), ...(msg.horse_channels || [])]
        .filter((c) => c.unit === "length")
        .map((c) => c.name);
      page.tickRate = msg.tick_rate;
      const all = [...(msg.channels || []), ...(msg.horse_channels || [])].map((c) => c.name);
      chains = { tail: groupChain(all, "tail"), braid: groupChain(all, "braid") };
      $("plot-add").innerHTML = `<option value="">add a channel…</option>${all.map((n) => `<option>${n}</option>`).join("")}`;
      if (plots.chosen.length === 0) plots.chosen = DEFAULT_PLOTS.filter((n) => all.includes(n));
      chips();
      controls.load(msg.channels || []);
    },
    frame(frame) {
      latest = frame;
      frameCount += 1;
      page.frames += 1;
      page.seq = frame.seq;
      page.driver = frame.driver;
      plots.push(frame.t, frame.values);
      saddle.frame(frame);
    },
    status(msg) {
      page.status = msg;
      controls.status(msg);
      platform.status(msg);
    },
    state(state, why) {
      page.state = state;
      page.connected = state === "live";
      const pill = $("conn");
      pill.className = `pill ${state}`;
      pill.dataset.state = state;
      pill.textContent = state === "live" ? "live" : state === "gone" ? "service gone" : "connecting…";
      $("gone").hidden = state !== "gone";
      $("gone-why").textContent = why || "no connection";
    },
  }, 120, controlToken());
  link.subscription = SaddlePanel.subscription();
  page.link = link;
  setInterval(() => controls.refresh(), 1000);

  // Dynamic resolution: render fewer pixels while the page runs below 40 fps (a busy
  // machine, software WebGL), go back up after 3 s above 55 fps.
  const SCALES = [1, 0.75, 0.5];
  let scaleStep = 0;
  let goodSeconds = 0;
  page.renderScale = 1;
  let scaleLocked = false;
  page.setRenderScale = (scale) => {
    scaleLocked = scale !== null;
    if (scaleLocked) view.setScale((page.renderScale = scale));
  };
  function adaptScale() {
    if (scaleLocked) return;
    if (page.fps < 40 && scaleStep < SCALES.length - 1) {
      scaleStep += 1;
      goodSeconds = 0;
    } else if (page.fps > 55 && scaleStep > 0 && ++goodSeconds >= 3) {
      scaleStep -= 1;
      goodSeconds = 0;
    } else return;
    page.renderScale = SCALES[scaleStep];
    view.setScale(page.renderScale);
  }

  let rafCount = 0;
  let lastSecond = performance.now();
  let lastLatest = null;
  let lastPlot = 0;
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
      $("rates").textContent = `${page.frameRate.toFixed(0)} frames/s in · ${page.fps.toFixed(0)} fps${page.tickRate ? ` · tick ${page.tickRate} Hz` : ""}${link.restarts ? ` · service restarted ×${link.restarts}` : ""}`;
      $("driver").textContent = page.driver ? `driver: ${page.driver}` : "";
    }
    if (latest && latest !== lastLatest) {
      lastLatest = latest;
      page.values = latest.values;
      let values = latest.values;
      if (toMetres !== 1) {
        values = { ...values };
        for (const n of lengthChannels) if (n in values) values[n] *= toMetres;
      }
      const hv = { ...values };
      const follow = $("follow").checked;
      if (follow) {
        hv["root.tx"] = 0;
        hv["root.tz"] = 0;
      }
      const horsePose = solve(horseRig, hv);
      const riderPose = solve(riderRig, values);
      const horseW = placed(horsePose, [0, 0, 0, 1], [0, 0, 0]);
      const si = horseRig.index.saddle;
      const riderW = placed(riderPose, horseW.rotations[si], horseW.positions[si]);
      const byName = (rig, list) => Object.fromEntries(rig.bones.map((b, i) => [b.name, list[i]]));
      page.pose = {
        // Built when read (tests, the console), not every animation frame.
        get rider() {
          return byName(riderRig, riderPose.localRotations);
        },
        get horse() {
          return byName(horseRig, horsePose.localRotations);
        },
        get riderWorld() {
          return byName(riderRig, riderW.positions);
        },
      };
      // Chain positions (tail_NN.t*, braid_NN.t*) are world positions; on the treadmill the
      // horse's travel (root.tx, root.tz) is taken out as it is for the horse.
      const rootTx = follow ? values["root.tx"] || 0 : 0;
      const rootTz = follow ? values["root.tz"] || 0 : 0;
      const toHorse = (p) => [p[0] - rootTx, p[1], p[2] - rootTz];
      const ti = horseRig.index.tailRoot;
      view.chain("tail", chainPoints(values, chains.tail, horseW.positions[ti], horseW.rotations[ti], toHorse));
      const hi = riderRig.index.head;
      view.chain("braid", chainPoints(values, chains.braid, riderW.positions[hi], riderW.rotations[hi], toHorse));
      view.update(horseW, riderW, follow ? values["root.tx"] || 0 : 0);
    } else if (!latest) {
      const horseW = placed(solve(horseRig, {}), [0, 0, 0, 1], [0, 0, 0]);
      const si = horseRig.index.saddle;
      view.update(horseW, placed(solve(riderRig, {}), horseW.rotations[si], horseW.positions[si]), 0);
    }
    if (now - lastPlot >= 33) {
      lastPlot = now; // plots at <= 30 Hz: enough for the eye, half the canvas work
      plots.draw();
    }
    page.tickMs = 0.95 * (page.tickMs || 0) + 0.05 * (performance.now() - t0); // JS time per animation frame
    requestAnimationFrame(tick);
  }
  requestAnimationFrame(tick);
}

bindEstop();
window.addEventListener("error", (ev) => page.errors.push(String(ev.message)));
start().catch((err) => {
  page.errors.push(String(err));
  $("message").textContent = `page failed to start: ${err}`;
});
