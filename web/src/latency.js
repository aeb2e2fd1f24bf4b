// Latency panel: the service's live latency histograms (GET /api/latency), over the last
// 10 s, against the goal of one tick + 1 ms. p99 turns red when it misses the goal. After
// the goal: whether the tick is phase-locked to its live input (docs/performance.md).

import { api } from "./controls.js";

const ROWS = [
  ["ingest_to_send", "horse in → rider sent"],
  ["ingest_to_wire", "horse in → rig goal out"],
  ["tick_lateness", "tick lateness"],
];

const ms = (s) => (s === null || s === undefined ? "–" : (s * 1e3).toFixed(2));

// "tick locked 0.45 ms after input" / "tick not locked" / "" (the lock is off).
export function phaseText(lock) {
  if (!lock) return "";
  return lock.locked && lock.lead !== null ? `· tick locked ${ms(lock.lead)} ms after input` : "· tick not locked";
}

export class LatencyPanel {
  constructor(parent, before = null) {
    this.root = document.createElement("details");
    this.root.id = "latency";
    this.root.open = true;
    this.root.innerHTML =
      `<summary>Latency <span class="muted" id="latency-goal"></span> <span class="muted" id="latency-phase"></span></summary>` +
      `<table><thead><tr><th>last 10 s</th><th>p50 ms</th><th>p99 ms</th><th>max ms</th><th>n</th></tr></thead>` +
      `<tbody>${ROWS.map(([key, label]) => `<tr data-key="${key}"><td>${label}</td><td></td><td></td><td></td><td></td></tr>`).join("")}</tbody></table>`;
    parent.insertBefore(this.root, before);
    this.latest = null;
  }

  async refresh() {
    let answer;
    try {
      answer = await api("GET", "/api/latency?window=10");
    } catch {
      return; // the service is gone or wants a token: the connection pill says so
    }
    this.latest = answer;
    this.root.querySelector("#latency-goal").textContent = `goal p99 ≤ ${ms(answer.goal)} ms`;
    this.root.querySelector("#latency-phase").textContent = phaseText(answer.phase_lock);
    for (const row of this.root.querySelectorAll("tbody tr")) {
      const h = answer.histograms[row.dataset.key];
      const w = h ? h.window : null;
      const cells = row.children;
      cells[1].textContent = ms(w && w.p50);
      cells[2].textContent = ms(w && w.p99);
      cells[3].textContent = ms(w && w.max);
      cells[4].textContent = w ? w.count : "–";
      const late = row.dataset.key !== "tick_lateness" && w && w.p99 !== null && w.p99 > answer.goal;
      cells[2].classList.toggle("bad", Boolean(late));
      row.hidden = row.dataset.key === "ingest_to_wire" && (!h || h.total.count === 0);
    }
  }
}
