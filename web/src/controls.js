// The control panel: REST calls to the service (source, moves, presets, weights,
// animator, record, e-stop, reset) and the rig's servo table. Paths: docs/protocol.md.

import { filterWeights, renderWeights } from "./weights.js";

const $ = (id) => document.getElementById(id);

/**
 * The control token, when the service requires one (bound beyond loopback): opened as
 * `/#token=...` (a fragment never reaches the server or its logs), kept for the tab.
 */
export function controlToken() {
  const m = location.hash.match(/token=([^&]+)/);
  if (m) {
    sessionStorage.setItem("riderlive.token", decodeURIComponent(m[1]));
    history.replaceState(null, "", location.pathname + location.search);
  }
  return sessionStorage.getItem("riderlive.token");
}

/** A REST call; the JSON answer (or a Blob with `as = "blob"`); throws with the service's reason. */
export async function api(method, path, body, as = "json") {
  const init = { method, headers: {} };
  const token = controlToken();
  if (token) init.headers.authorization = `Bearer ${token}`;
  if (body !== undefined) {
    init.headers["content-type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const res = await fetch(path, init);
  if (res.ok && as === "blob") return res.blob();
  const text = await res.text();
  let data = null;
  try {
    data = text ? JSON.parse(text) : null;
  } catch {
    data = null;
  }
  if (res.status === 401 || res.status === 403) throw new Error(`${method} ${path}: the service wants a control token (open the page as /#token=...)`);
  if (!res.ok) throw new Error(`${method} ${path}: ${res.status} ${data && data.detail ? JSON.stringify(data.detail) : text}`);
  return data;
}

export function say(text, bad = false) {
  const m = $("message");
  m.textContent = text;
  m.style.color = bad ? "var(--bad)" : "";
}

/**
 * The header's alert: the last control that failed and why (the service's status and reason),
 * in sight whatever panel is open; cleared when that control next succeeds, or by a click.
 */
function alertFailure(what, message) {
  const a = $("alert");
  if (!a) return;
  a.textContent = `${what} failed: ${message}`;
  a.dataset.what = what;
  a.hidden = false;
}

function clearAlert(what) {
  const a = $("alert");
  if (a && !a.hidden && a.dataset.what === what) a.hidden = true;
}

export async function attempt(what, fn) {
  try {
    const out = await fn();
    say(`${what}: ok`);
    clearAlert(what);
    return out;
  } catch (err) {
    say(`${what}: ${err.message}`, true);
    alertFailure(what, err.message);
    return null;
  }
}

/** Calls `send(value)` at most every `ms`, always with the latest value. */
function throttled(send, ms = 80) {
  let pending = null;
  let timer = null;
  return (value) => {
    pending = value;
    if (timer) return;
    timer = setTimeout(async () => {
      timer = null;
      const v = pending;
      pending = null;
      await send(v);
    }, ms);
  };
}

function slider(parent, key, value, lo, hi, onInput) {
  const label = document.createElement("label");
  const step = (hi - lo) / 400;
  label.innerHTML = `<span title="${key}">${key}</span><input type="range"><output></output>`;
  const input = label.querySelector("input");
  const out = label.querySelector("output");
  Object.assign(input, { min: lo, max: hi, step, value });
  input.dataset.key = key;
  out.textContent = (+value).toPrecision(3);
  input.addEventListener("input", () => {
    out.textContent = (+input.value).toPrecision(3);
    onInput(key, +input.value);
  });
  parent.appendChild(label);
  return input;
}

/**
 * The e-stop: bound first, before anything else on the page can fail. Click, or the
 * space bar anywhere but in a text field (a focused button loses focus first, so the
 * space bar never presses it as well).
 */
export function bindEstop(after = () => {}) {
  const fire = async () => {
    $("estop").classList.add("engaged"); // at once; the service's answer and status confirm or clear it
    await attempt("E-STOP", () => api("POST", "/api/estop"));
    after();
  };
  $("estop").addEventListener("click", fire);
  document.addEventListener("keydown", (ev) => {
    if (ev.code !== "Space" || ev.repeat) return;
    const t = ev.target;
    if (t instanceof HTMLInputElement && t.type !== "range" && t.type !== "checkbox") return;
    if (t instanceof HTMLSelectElement || t instanceof HTMLTextAreaElement) return;
    ev.preventDefault();
    if (document.activeElement instanceof HTMLElement) document.activeElement.blur();
    fire();
  });
}

export class Controls {
  constructor(state) {
    this.state = state;
    this.riderChannels = [];
    const changes = {};
    const patch = throttled(async () => {
      const body = { ...changes };
      for (const k in changes) delete changes[k];
      await attempt("weights", () => api("PATCH", "/api/params", body));
    });
    this.onParam = (key, value) => {
      changes[key] = value;
      patch();
    };
    this.offsets = {};
    this.gains = {};
    const putAnimator = throttled(() => attempt("animator", () => api("PUT", "/api/animator", { offsets: this.offsets, gains: this.gains })));
    this.onOffset = (key, value) => {
      this.offsets[key] = value;
      putAnimator();
    };
    this.bind();
  }

  bind() {
    // After a reset, failed or not, the latch and the devices are read back from the service: the
    // header then says what is true (a refused reset leaves the e-stop latched, and says so).
    $("reset").addEventListener("click", async () => {
      await attempt("reset", () => api("POST", "/api/reset"));
      if (this.state.status) await this.state.status.fetchDevices();
      await this.refresh();
    });
    $("alert").addEventListener("click", () => ($("alert").hidden = true));
    $("src-speed").addEventListener("input", () => ($("src-speed-out").textContent = (+$("src-speed").value).toFixed(1)));
    $("src-kind").addEventListener("change", () => this.showSourceRows());
    $("src-gait").addEventListener("change", () => this.fitSpeed(true));
    api("GET", "/api/horse").then((horse) => {
      this.gaits = horse.gaits;
      this.fitSpeed(false);
    }, () => {});
    $("src-apply").addEventListener("click", () => this.applySource());
    for (const move of ["jump", "rear", "stop", "buck"]) {
      const b = document.createElement("button");
      b.id = `move-${move}`;
      b.textContent = move[0].toUpperCase() + move.slice(1);
      b.title = `ask the procedural horse for a ${move}`;
      b.addEventListener("click", () => attempt(move, () => api("POST", "/api/horse/perform", { move })));
      $("moves").appendChild(b);
    }
    $("preset").addEventListener("change", async () => {
      await attempt("preset", () => api("PUT", "/api/preset", { name: $("preset").value }));
      await this.loadParams();
    });
    $("param-filter").addEventListener("input", () => filterWeights());
    $("rec-start").addEventListener("click", () => attempt("record", () => api("POST", "/api/record/start", {})).then(() => this.refresh()));
    $("rec-stop").addEventListener("click", () => attempt("stop", () => api("POST", "/api/record/stop")).then(() => this.refresh()));
    $("anim-zero").addEventListener("click", () => {
      for (const k in this.offsets) this.offsets[k] = 0;
      for (const input of $("animator").querySelectorAll("input")) input.value = 0;
      attempt("animator", () => api("PUT", "/api/animator", { offsets: this.offsets, gains: this.gains }));
    });
    this.showSourceRows();
  }

  /** The speed slider spans the chosen gait's range (GET /api/horse); `reset`: at its own speed. */
  fitSpeed(reset) {
    const gait = this.gaits && this.gaits[$("src-gait").value];
    if (!gait) return;
    const slider = $("src-speed");
    [slider.min, slider.max] = gait.speed;
    if (reset || +slider.value < gait.speed[0] || +slider.value > gait.speed[1]) slider.value = gait.default;
    $("src-speed-out").textContent = (+slider.value).toFixed(1);
  }

  showSourceRows() {
    const kind = $("src-kind").value;
    for (const row of document.querySelectorAll("[data-for]")) row.hidden = row.dataset.for !== kind;
  }

  async applySource(take) {
    let body;
    const kind = take ? "replay" : $("src-kind").value;
    if (kind === "procedural") body = { kind, gait: $("src-gait").value, speed: +$("src-speed").value };
    else if (kind === "replay") body = { kind, take: take || $("src-take").value };
    else body = { kind: "live" };
    await attempt(`source ${kind}`, () => api("PUT", "/api/source", body));
    this.refresh();
  }

  /** Everything that only needs loading once per connection. */
  async load(riderChannels) {
    this.riderChannels = riderChannels;
    const presets = await attempt("presets", () => api("GET", "/api/presets"));
    if (presets) {
      const names = presets.presets || presets.names || [];
      $("preset").innerHTML = names.map((n) => `<option>${typeof n === "string" ? n : n.name}</option>`).join("");
      if (presets.current) $("preset").value = presets.current;
    }
    await this.loadParams();
    const anim = await attempt("animator", () => api("GET", "/api/animator"));
    if (anim) {
      this.offsets = { ...(anim.offsets || {}) };
      this.gains = { ...(anim.gains || {}) };
    }
    const box = $("animator");
    box.innerHTML = "";
    for (const c of riderChannels) {
      const span = c.unit === "deg" ? 30 : c.unit === "length" ? 0.15 : 5;
      slider(box, c.name, this.offsets[c.name] || 0, -span, span, this.onOffset);
    }
    await this.refresh();
  }

  async loadParams() {
    const params = await attempt("params", () => api("GET", "/api/params"));
    if (!params) return;
    let groups = null;
    try {
      groups = (await api("GET", "/api/params/groups")).groups;
    } catch {
      /* an older service: grouped by the keys' prefixes */
    }
    renderWeights(params, groups, this.onParam);
  }

  /** State, takes: polled about once a second. */
  async refresh() {
    let state;
    try {
      state = await api("GET", "/api/state");
    } catch {
      return;
    }
    this.state.service = state;
    const src = state.source || {};
    if (!this.sourceShown && src.kind) {
      this.sourceShown = true;
      $("src-kind").value = src.kind;
      if (src.gait) $("src-gait").value = src.gait;
      this.fitSpeed(true);
      if (typeof src.speed === "number") $("src-speed").value = src.speed;
      $("src-speed-out").textContent = (+$("src-speed").value).toFixed(1);
      this.showSourceRows();
    }
    $("src-now").textContent = src.kind ? `now: ${src.kind}${src.gait ? ` ${src.gait}` : ""}${src.take ? ` ${src.take}` : ""}` : "";
    const rec = state.recording;
    $("rec-now").textContent = rec ? `recording ${rec.name} (${rec.rows} rows)` : "";
    if (this.onState) this.onState(state);
    if (this.takes) await this.takes.refresh();
  }

  /** The servo table of a rig (`rig.servos` of a status message), shown while a rig is attached. */
  servos(rig) {
    const servos = rig ? rig.servos : null;
    if (!Array.isArray(servos) || servos.length === 0) {
      $("rig").hidden = true;
      return;
    }
    $("rig").hidden = false;
    const num = (v) => (typeof v === "number" ? v.toFixed(1) : "—");
    const text = (v) => String(v).replace(/[&<>"]/g, (c) => `&#${c.charCodeAt(0)};`);
    $("servos").tBodies[0].innerHTML = servos
      .map((sv) => {
        const errs = Array.isArray(sv.hardware_error) ? sv.hardware_error.join(", ") : sv.hardware_error || "";
        const track = typeof sv.tracking_error_deg === "number" ? ` title="tracking error ${num(sv.tracking_error_deg)}°"` : "";
        return `<tr class="${errs ? "fault" : ""}"><td>${text(sv.name ?? sv.id)}</td><td>${num(sv.goal_deg)}</td><td${track}>${num(sv.present_deg)}</td><td>${num(sv.temperature_c)}</td><td>${errs ? text(errs) : "—"}</td></tr>`;
      })
      .join("");
  }
}
