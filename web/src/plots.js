// Scrolling plots of chosen channels over the last WINDOW seconds (canvas 2D).
// Every channel's history is kept (a ring of frames), so a newly chosen channel
// shows its past at once.

export const WINDOW = 10;
const COLORS = ["#4da3ff", "#3ecf8e", "#f5a524", "#e5484d", "#b58cff", "#45d3d3", "#ff7ab8", "#c2c96b"];

export class Plots {
  constructor(canvas, capacity = 2400) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.capacity = capacity;
    this.times = new Float64Array(capacity);
    this.series = new Map(); // name -> Float64Array
    this.head = 0;
    this.count = 0;
    this.chosen = [];
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

  draw() {
    const c = this.canvas;
    const w = c.clientWidth;
    const h = c.clientHeight;
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    const ctx = this.ctx;
    ctx.clearRect(0, 0, w, h);
    if (this.count < 2 || this.chosen.length === 0 || h < 10) return;
    const last = (this.head - 1 + this.capacity) % this.capacity;
    const tEnd = this.times[last];
    const lanes = this.chosen.length;
    const laneH = h / lanes;
    ctx.font = "11px system-ui, sans-serif";
    this.chosen.forEach((name, lane) => {
      const s = this.series.get(name);
      const top = lane * laneH;
      ctx.strokeStyle = "#2a2f36";
      ctx.beginPath();
      ctx.moveTo(0, top + laneH);
      ctx.lineTo(w, top + laneH);
      ctx.stroke();
      if (!s) return;
      let lo = Infinity;
      let hi = -Infinity;
      let first = -1;
      for (let k = 0; k < this.count; k++) {
        const i = (last - k + this.capacity) % this.capacity;
        if (tEnd - this.times[i] > WINDOW) break;
        first = k;
        const v = s[i];
        if (v < lo) lo = v;
        if (v > hi) hi = v;
      }
      if (!(hi >= lo)) return;
      const pad = Math.max((hi - lo) * 0.1, 1e-6);
      lo -= pad;
      hi += pad;
      ctx.strokeStyle = this.color(name);
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      let started = false;
      for (let k = first; k >= 0; k--) {
        const i = (last - k + this.capacity) % this.capacity;
        const v = s[i];
        if (!Number.isFinite(v)) continue;
        const x = w - ((tEnd - this.times[i]) / WINDOW) * w;
        const y = top + laneH - ((v - lo) / (hi - lo)) * laneH;
        if (started) ctx.lineTo(x, y);
        else ctx.moveTo(x, y);
        started = true;
      }
      ctx.stroke();
      const now = s[last];
      ctx.fillStyle = this.color(name);
      ctx.fillText(`${name} ${Number.isFinite(now) ? now.toFixed(3) : "—"}  [${(lo + pad).toFixed(3)} … ${(hi - pad).toFixed(3)}]`, 6, top + 12);
    });
  }
}
