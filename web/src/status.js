// Honest status lines: what drives the rider, the e-stop (latched, and what it stopped),
// the devices and their Arm / Disarm. Sources: the websocket's status messages (pushed
// on change), GET /api/state (the chosen source, producers) and GET /api/devices
// (fetched on connect and after every safety action). Paths: docs/protocol.md.

const $ = (id) => document.getElementById(id);
const ARMABLE = ["disarmed", "parked"];
const MOVING = ["homing", "soft_start", "running"];

/**
 * Streamed input that a chosen source (procedural, replay) leaves unused: it does not drive
 * until the source is handed back (`PUT /api/source {"kind": "live"}`, Source: live, Apply).
 */
export function ignoredInput(source, state) {
  const kind = source && source.kind;
  if (kind !== "procedural" && kind !== "replay") return "";
  const producers = ((state && state.arbitration) || {}).producers || [];
  if (!producers.length) return "";
  const names = producers.map((p) => p.name || `producer ${p.id}`).join(", ");
  return ` · live input from ${names} ignored: Source "live" hands back`;
}

/**
 * One line saying what drives the rider, and how sure we are (ok / warn / bad). What the
 * horse does (gait, measured speed) is the header's horse line (horsenow.js), not the request.
 */
export function describeDriver(source, driver, state, tick) {
  if (tick && tick.tick_up === false) return [`tick down — ${tick.restarting ? "restarting" : "stopped"}${tick.reason ? ` (${tick.reason})` : ""}`, "bad"];
  const kind = source && source.kind;
  if (!driver) return ["waiting for frames…", "warn"];
  const ignored = ignoredInput(source, state);
  if (kind === "replay") return [`replay of ${source.take}${driver !== "input" ? ` (${driver})` : ""}${ignored}`, ignored ? "warn" : "ok"];
  if (kind === "procedural") return [`procedural horse (chosen)${ignored}`, ignored ? "warn" : "ok"];
  if (driver === "input") {
    const arb = (state && state.arbitration) || {};
    const producer = (arb.producers || []).find((p) => p.id === arb.active);
    return [`live input${producer ? ` from ${producer.name || `producer ${producer.id}`}` : ""}`, "ok"];
  }
  if (driver === "procedural") return ["procedural — waiting for live input", "warn"];
  if (driver === "neutral") return ["neutral pose — waiting for live input", "warn"];
  return [`driver: ${driver}`, "warn"];
}

/** What the e-stop stopped: each device's name and state, or that no rig is attached. */
export function describeEstop(latched, devices) {
  if (!latched) return null;
  const stopped = devices.length
    ? `stopped: ${devices.map((d) => `${d.name} (${d.state}${d.outputs_off_confirmed ? ", outputs off confirmed" : ""})`).join(", ")}`
    : "no rig attached: nothing was moving, nothing to stop";
  return `E-STOP LATCHED · ${stopped} · Reset clears it (never re-arms)`;
}

export class Status {
  constructor(page, api, attempt) {
    this.page = page;
    this.api = api;
    this.attempt = attempt;
    this.devices = [];
    this.estop = false;
    this.tick = null;
    this.source = null;
    this.state = null;
    $("arm").addEventListener("click", () => this.first() && this.act(`arm ${this.first().name}`, "/api/arm", { device: this.first().name, by: "page" }));
    $("disarm").addEventListener("click", () => this.act("disarm", "/api/disarm", this.first() ? { device: this.first().name, by: "page" } : {}));
  }

  first() {
    return this.devices[0] || null;
  }

  async act(what, path, body) {
    await this.attempt(what, () => this.api("POST", path, body));
    await this.fetchDevices();
  }

  /** GET /api/devices: on connect and after each safety action. */
  async fetchDevices() {
    try {
      const d = await this.api("GET", "/api/devices");
      this.setDevices(d.devices || [], Boolean(d.estop));
    } catch {
      /* the status messages keep it current */
    }
  }

  /** A status message from /ws/rider (`devices`, `rig`, `estop`, tick supervision). */
  fromStatus(msg) {
    this.tick = msg;
    let devices = Array.isArray(msg.devices) ? msg.devices : null;
    if (msg.rig && (!devices || devices.length === 0)) devices = [msg.rig];
    this.setDevices(devices || this.devices, typeof msg.estop === "boolean" ? msg.estop : this.estop);
  }

  fromState(state) {
    this.state = state;
    this.source = state.source || null;
    this.show();
  }

  setDevices(devices, estop) {
    this.devices = devices;
    this.estop = estop;
    this.page.estop = estop;
    this.page.devices = devices;
    this.show();
  }

  show() {
    const [text, level] = describeDriver(this.source, this.page.driver, this.state, this.tick);
    $("driver").textContent = text;
    $("driver").className = `status ${level}`;
    this.page.driverText = text;
    $("estop").classList.toggle("engaged", this.estop);
    const stop = describeEstop(this.estop, this.devices);
    $("estop-state").hidden = !stop;
    $("estop-state").textContent = stop || "";
    const first = this.first();
    const state = first ? first.state : "";
    $("arm").hidden = $("disarm").hidden = !first;
    $("arm").disabled = this.estop || !ARMABLE.includes(state);
    $("disarm").disabled = !MOVING.includes(state);
    const fault = (d) => (d.fault ? ` · fault: ${d.fault.message || d.fault.kind || JSON.stringify(d.fault)}` : "");
    $("rigstate").textContent = first
      ? this.devices.map((d) => `${d.name || "rig"}: ${d.state}${d.detail ? ` (${d.detail})` : ""}${fault(d)}`).join(" · ")
      : "no rig attached";
    $("rigstate").className = `status ${first && first.fault ? "bad" : first && MOVING.includes(state) ? "warn" : ""}`;
    this.showDevices();
  }

  showDevices() {
    const box = $("devices");
    if (!this.devices.length) {
      box.textContent = "no rig attached";
      return;
    }
    box.textContent = "";
    for (const d of this.devices) {
      const row = document.createElement("div");
      row.className = "device";
      const label = document.createElement("span");
      label.textContent = `${d.name} (${d.kind || "device"}): ${d.state}${d.armed_by ? `, armed by ${d.armed_by}` : ""}`;
      const arm = document.createElement("button");
      arm.textContent = "Arm";
      arm.disabled = this.estop || !ARMABLE.includes(d.state);
      arm.addEventListener("click", () => this.act(`arm ${d.name}`, "/api/arm", { device: d.name, by: "page" }));
      const disarm = document.createElement("button");
      disarm.textContent = "Disarm";
      disarm.disabled = !MOVING.includes(d.state);
      disarm.addEventListener("click", () => this.act(`disarm ${d.name}`, "/api/disarm", { device: d.name, by: "page" }));
      row.append(label, arm, disarm);
      box.appendChild(row);
    }
  }
}
