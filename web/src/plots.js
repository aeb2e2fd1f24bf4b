// Scrolling plots of chosen channels (canvas 2D): one lane per channel, at least
// LANE_MIN px tall (the box scrolls when they do not fit), a time axis in seconds before
// now (its own canvas under the box: always in sight, however many lanes scroll), each lane's unit, a selectable window (up to MAX_WINDOW s), and lanes scaled to
// their own range or sharing one range per unit. Every channel's history is kept, so a
// newly chosen channel shows its past at once. draw() repaints only when a frame came or
// a setting or the size changed, with 1 px (hairline) traces: a software 2D canvas strokes
// those several times faster than wider ones (docs/performance.md, "Previs page").

export const WINDOWS = [2, 5, 10, 30];
export const MAX_WINDOW = 30;
export const LANE_MIN = 64;
const AXIS_H = 18;
const COLORS = ["#4da3ff", "#3ecf8e", "#f5a524", "#e5484d", "#b58cff", "#45d3d3", "#ff7ab8", "#c2c96b"];

function niceStep(span, ticks) {
  const raw = span / ticks;
  const p = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 5, 10].map((m) => m * p).find((s) => s >= raw) || raw;
}

export class Plots {
  constructor(canvas, axis = null, capacity = 120 * (MAX_WINDOW + 2)) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.axis = axis; // the time axis's canvas, outside the scrolling box (null: drawn under the lanes)
    this.capacity = capacity;
    this.times = new Float64Array(capacity);
    this.series = new Map(); // name -> Float64Array
    this.units = {}; // name -> unit label
    this.head = 0;
    this.count = 0;
    this.chosen = [];
    this.window = 10;
    this.ownScale = true;
    this.drawn = null; // what the canvas shows: see draw()
    // The box's size, kept by a ResizeObserver (no forced layout in draw()).
    const box = canvas.parentElement;
    this.boxSize = [box.clientWidth, box.clientHeight];
    if (typeof ResizeObserver !== "undefined")
      new ResizeObserver(() => (this.boxSize = [box.clientWidth, box.clientHeight])).observe(box);
  }

  push(t, values) {
    const i = this.head;
    this.times[i] = t;
    for (const name in values) {
      let s = this.series.get(name);
      if (!s) {
        s = new Float64Array(this.capacity).fill(NaN);
        this.series.set(name, s);
      }
      s[i] = values[name];
    }
    this.head = (i + 1) % this.capacity;
    this.count = Math.min(this.count + 1, this.capacity);
  }

  /** Values of `name` over the last `seconds`, oldest first. */
  recent(name, seconds) {
    const s = this.series.get(name);
    if (!s || this.count === 0) return [];
    const last = (this.head - 1 + this.capacity) % this.capacity;
    const out = [];
    for (let k = 0; k < this.count; k++) {
      const i = (last - k + this.capacity) % this.capacity;
      if (this.times[last] - this.times[i] > seconds) break;
      out.push(s[i]);
    }
    return out.reverse();
  }

  color(name) {
    return COLORS[this.chosen.indexOf(name) % COLORS.length];
  }

  /** [lo, hi] of each chosen channel over the window: its own, or shared by its unit. */
  ranges(last, tEnd) {
    const own = this.chosen.map((name) => {
      const s = this.series.get(name);
      let lo = Infinity;
      let hi = -Infinity;
      if (s)
        for (let k = 0; k < this.count; k++) {
          const i = (last - k + this.capacity) % this.capacity;
          if (tEnd - this.times[i] > this.window) break;
          const v = s[i];
          if (v < lo) lo = v;
          if (v > hi) hi = v;
        }
      return [lo, hi];
    });
    if (this.ownScale) return own;
    const byUnit = {};
    this.chosen.forEach((n, k) => {
      const u = this.units[n] || "";
      const r = byUnit[u] || [Infinity, -Infinity];
      byUnit[u] = [Math.min(r[0], own[k][0]), Math.max(r[1], own[k][1])];
    });
    return this.chosen.map((n) => byUnit[this.units[n] || ""]);
  }

  draw() {
    const c = this.canvas;
    const [w, boxH] = this.boxSize;
    const lanes = Math.max(1, this.chosen.length);
    const axisH = this.axis ? 0 : AXIS_H; // the lanes' canvas keeps room for the axis only without its own
    const h = Math.max(boxH, lanes * LANE_MIN + axisH);
    const key = `${this.head} ${this.count} ${w} ${h} ${this.window} ${this.ownScale} ${this.chosen.join(",")} ${Object.keys(this.units).length}`;
    if (key === this.drawn) return;
    this.drawn = key;
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
      c.style.height = `${h}px`;
    }
    const ctx = this.ctx;
    ctx.clearRect(0, 0, w, h);
    const ax = this.axis ? this.axis.getContext("2d") : ctx;
    if (this.axis && (this.axis.width !== w || this.axis.height !== AXIS_H)) {
      this.axis.width = w;
      this.axis.height = AXIS_H;
    }
    if (this.axis) ax.clearRect(0, 0, w, AXIS_H);
    if (this.count < 2 || this.chosen.length === 0 || w < 40) return;
    const last = (this.head - 1 + this.capacity) % this.capacity;
    const tEnd = this.times[last];
    const laneH = (h - axisH) / lanes;
    const labelY = this.axis ? AXIS_H - 5 : h - 5;
    const x0 = 58; // value labels on the left
    const plotW = w - x0 - 6;
    const xOf = (age) => x0 + plotW - (age / this.window) * plotW;
    ctx.font = ax.font = "11px system-ui, sans-serif";
    // Time axis: seconds before now, with a faint grid through the lanes.
    const step = niceStep(this.window, 6);
    ax.textAlign = "center";
    this.axisLabels = [];
    for (let age = 0; age <= this.window + 1e-9; age += step) {
      const x = xOf(age);
      ctx.strokeStyle = "#242a31";
      ctx.beginPath();
      ctx.moveTo(x, 0);
      ctx.lineTo(x, h - axisH);
      ctx.stroke();
      ax.fillStyle = "#8a939d";
      const label = age === 0 ? "now" : `-${+age.toFixed(2)} s`;
      ax.fillText(label, Math.min(Math.max(x, x0 + 14), w - 14), labelY);
      this.axisLabels.push(label);
    }
    const ranges = this.ranges(last, tEnd);
    this.chosen.forEach((name, lane) => {
      const s = this.series.get(name);
      const top = lane * laneH;
      ctx.strokeStyle = "#39414b";
      ctx.beginPath();
      ctx.moveTo(0, top + laneH);
      ctx.lineTo(w, top + laneH);
      ctx.stroke();
      let [lo, hi] = ranges[lane];
      if (!s || !(hi >= lo)) return;
      const pad = Math.max((hi - lo) * 0.08, 1e-6);
      lo -= pad;
      hi += pad;
      const yOf = (v) => top + laneH - ((v - lo) / (hi - lo)) * laneH;
      ctx.strokeStyle = this.color(name);
      ctx.beginPath();
      let started = false;
      for (let k = this.count - 1; k >= 0; k--) {
        const i = (last - k + this.capacity) % this.capacity;
        const age = tEnd - this.times[i];
        const v = s[i];
        if (age > this.window || !Number.isFinite(v)) continue;
        if (started) ctx.lineTo(xOf(age), yOf(v));
        else ctx.moveTo(xOf(age), yOf(v));
        started = true;
      }
      ctx.stroke();
      const unit = this.units[name] ? ` ${this.units[name]}` : "";
      ctx.textAlign = "right";
      ctx.fillStyle = "#8a939d";
      ctx.fillText(`${(hi - pad).toPrecision(3)}`, x0 - 4, top + 11);
      ctx.fillText(`${(lo + pad).toPrecision(3)}`, x0 - 4, top + laneH - 3);
      ctx.textAlign = "left";
      const now = s[last];
      ctx.fillStyle = this.color(name);
      ctx.fillText(`${name}  ${Number.isFinite(now) ? now.toFixed(3) : "—"}${unit}`, x0 + 6, top + 12);
    });
  }
}
