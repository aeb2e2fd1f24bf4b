// The saddle panel: the saddle pose of the tick's horse (whatever drives it) and, while a
// saddle stream (/ws/saddle) drives, the estimator's gait, stride frequency and lock.
// Protocol: docs/protocol.md ("Saddle"); the method and its states: docs/saddle.md.
// The panel builds its own DOM inside `parent` and redraws at most 10 times a second.

const AXES = [
  ["saddle.tx", "fore-aft", "m"],
  ["saddle.ty", "up", "m"],
  ["saddle.tz", "side", "m"],
  ["saddle.rx", "roll", "°"],
  ["saddle.ry", "yaw", "°"],
  ["saddle.rz", "pitch", "°"],
];
const LOCK_TEXT = {
  locked: "locked",
  searching: "searching (no gait fits: hooves standing)",
  still: "still (halt)",
  no_signal: "no signal (too sparse or nothing yet)",
};

export class SaddlePanel {
  /** @param {HTMLElement} parent where the panel goes; @param {object} page window.riderlive */
  constructor(parent, page) {
    this.page = page;
    this.toMetres = 1;
    this.latest = null;
    this.drawn = null;
    page.saddle = { pose: null, estimate: null };
    const box = document.createElement("details");
    box.id = "saddle";
    box.open = true;
    box.innerHTML = `<summary>Saddle</summary>
      <table id="saddle-pose"><tbody>${AXES.map(
        ([name, what, unit]) => `<tr><td title="${name}">${what}</td><td data-axis="${name}">–</td><td>${unit}</td></tr>`,
      ).join("")}</tbody></table>
      <div class="row" id="saddle-estimate"><span class="muted">estimate: the input is not a saddle</span></div>`;
    parent.insertBefore(box, parent.querySelector("#message"));
    this.cells = Object.fromEntries([...box.querySelectorAll("[data-axis]")].map((c) => [c.dataset.axis, c]));
    this.estimateRow = box.querySelector("#saddle-estimate");
    setInterval(() => this.draw(), 100);
  }

  /** The subscription field to ask for (the link merges it into its subscribe). */
  static subscription() {
    return { saddle: true };
  }

  hello(toMetres) {
    this.toMetres = toMetres;
  }

  frame(frame) {
    if (Array.isArray(frame.saddle)) this.latest = frame;
  }

  draw() {
    const frame = this.latest;
    if (!frame || frame === this.drawn) return;
    this.drawn = frame;
    const pose = frame.saddle.map((v, i) => (i < 3 ? v * this.toMetres : v));
    this.page.saddle = { pose, estimate: frame.estimate || null, values: frame.values }; // values: the frame shown
    AXES.forEach(([name, , unit], i) => {
      const text = unit === "m" ? pose[i].toFixed(3) : pose[i].toFixed(1);
      if (this.cells[name].textContent !== text) this.cells[name].textContent = text;
    });
    const e = frame.estimate;
    if (!e) {
      this.setEstimate(`<span class="muted">estimate: the input is not a saddle</span>`);
      return;
    }
    const gait = e.gait || "–";
    const hz = e.stride_hz > 0 ? `${e.stride_hz.toFixed(2)} Hz` : "–";
    const age = e.age === null ? "" : ` · ${(e.age * 1000).toFixed(0)} ms old`;
    this.setEstimate(`<span class="pill ${e.lock === "locked" ? "live" : "connecting"}" data-lock="${e.lock}">${
      LOCK_TEXT[e.lock] || e.lock
    }</span><span data-gait="${gait}">gait ${gait}</span><span>stride ${hz}</span><span class="muted">phase ${e.phase.toFixed(2)}${age}</span>`);
  }

  /** Replace the estimate line only when its text changed (no DOM work, style or layout otherwise). */
  setEstimate(html) {
    if (html === this.estimateHtml) return;
    this.estimateHtml = html;
    this.estimateRow.innerHTML = html;
  }
}
