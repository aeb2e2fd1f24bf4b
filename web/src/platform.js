// The motion platform on the page: drawn under the horse in the 3D view (base, top plate
// and actuators, each coloured from green to red by how close it is to a soft limit) and a
// panel with its state, the firmware's, workspace use, limits hit and a live intensity
// slider (PATCH /api/platform). Fed by the tick's status (`msg.platform`, docs/platform.md).

import { BufferGeometry, Color, Float32BufferAttribute, Group, LineBasicMaterial, LineSegments } from "three";

const GREEN_HUE = 1 / 3;

/** Green (mid-range) to red (at a soft limit), for a closeness of 0..1. */
export function closenessColor(c) {
  const x = Math.min(Math.max(Number(c) || 0, 0), 1);
  return new Color().setHSL((1 - x) * GREEN_HUE, 0.85, 0.5);
}

export class PlatformView {
  /** `scene`: the 3D view's scene; `panel`: the element the panel is appended to. */
  constructor(scene, panel, token) {
    this.token = token;
    this.group = new Group();
    this.group.visible = false;
    this.geometry = new BufferGeometry();
    this.lines = new LineSegments(this.geometry, new LineBasicMaterial({ vertexColors: true }));
    this.group.add(this.lines);
    scene.add(this.group);
    this.el = document.createElement("details");
    this.el.id = "platform";
    this.el.open = true;
    this.el.hidden = true;
    this.el.innerHTML = `<summary>Platform</summary>
      <div class="row"><span id="platform-state"></span></div>
      <div class="row"><label>intensity <input id="platform-intensity" type="range" min="0" max="100" step="1" value="100">
        <output id="platform-intensity-out">100</output> %</label></div>
      <table id="platform-actuators"><thead><tr><th>actuator</th><th>target</th><th>measured</th><th>to limit</th></tr></thead><tbody></tbody></table>
      <div class="row muted" id="platform-link"></div>`;
    panel.appendChild(this.el);
    const slider = this.el.querySelector("#platform-intensity");
    slider.addEventListener("input", () => (this.el.querySelector("#platform-intensity-out").textContent = slider.value));
    slider.addEventListener("change", () => this.tune({ intensity: Number(slider.value) }));
    this.last = null;
  }

  async tune(changes) {
    const headers = { "Content-Type": "application/json" };
    if (this.token) headers.Authorization = `Bearer ${this.token}`;
    const reply = await fetch("api/platform", { method: "PATCH", headers, body: JSON.stringify(changes) });
    this.el.querySelector("#platform-link").textContent = reply.ok ? "" : `tune refused: ${await reply.text()}`;
  }

  /** One status message from the websocket. */
  status(msg) {
    const s = msg && msg.platform;
    this.last = s || null;
    this.group.visible = Boolean(s);
    this.el.hidden = !s;
    if (!s || !s.platform) return;
    const p = s.platform;
    const fw = p.firmware || {};
    const fault = s.fault ? ` · fault: ${s.fault.message}` : "";
    this.el.querySelector("#platform-state").textContent =
      `${s.name}: ${s.state}${s.detail ? ` (${s.detail})` : ""} · firmware ${fw.state || "?"}` +
      ` · workspace ${Math.round(100 * (p.workspace_use || 0))} %${fault}`;
    const slider = this.el.querySelector("#platform-intensity");
    if (document.activeElement !== slider && p.cueing) {
      slider.value = p.cueing.intensity;
      this.el.querySelector("#platform-intensity-out").textContent = Math.round(p.cueing.intensity);
    }
    const unit = p.unit === "m" ? 1000 : 1;
    const fmt = (v) => (v === null || v === undefined ? "–" : (v * unit).toFixed(1));
    this.el.querySelector("#platform-actuators").tBodies[0].innerHTML = (p.actuators || [])
      .map(
        (a) =>
          `<tr data-closeness="${a.closeness.toFixed(3)}"><td>${a.name}</td><td>${fmt(a.target)}</td><td>${fmt(a.measured)}</td>` +
          `<td style="color:#${closenessColor(a.closeness).getHexString()}">${Math.round(100 * (1 - a.closeness))} %</td></tr>`,
      )
      .join("");
    const host = (p.link && p.link.counters) || {};
    const bad = ["rx_crc", "rx_stale", "rx_gap"].map((k) => `${k} ${host[k] || 0}`).join(" · ");
    const hit = p.limits_hit || {};
    this.el.querySelector("#platform-link").textContent =
      `link ${p.link ? p.link.health : "?"} · ${bad} · silences ${host.silences || 0} · ` +
      `scaled back ${hit.scaled_back_frames || 0} · soft limit ${hit.soft_limit_frames || 0}`;
    this.draw(p);
  }

  /** Base joints, top joints and the actuators between them; the top plate sits at the ground. */
  draw(p) {
    const j = p.joints;
    if (!j || !j.base || !j.top) return;
    const lift = -Math.max(...j.top.map((t) => t[1]));
    const pts = [];
    const cols = [];
    const push = (a, b, color) => {
      pts.push(a[0], a[1] + lift, a[2], b[0], b[1] + lift, b[2]);
      cols.push(color.r, color.g, color.b, color.r, color.g, color.b);
    };
    const grey = new Color(0x8899aa);
    const n = j.base.length;
    for (let i = 0; i < n; i++) {
      push(j.base[i], j.base[(i + 1) % n], grey);
      push(j.top[i], j.top[(i + 1) % n], grey);
      push(j.base[i], j.top[i], closenessColor((p.actuators[i] || {}).closeness));
    }
    this.geometry.setAttribute("position", new Float32BufferAttribute(pts, 3));
    this.geometry.setAttribute("color", new Float32BufferAttribute(cols, 3));
    this.geometry.computeBoundingSphere();
  }
}
