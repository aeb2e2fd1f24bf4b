// What the horse really does, for the header: never the request. Gait and move come from
// the tick's status (the procedural horse's own state, pushed when they change); the speed
// is measured from the horse frames (root.tx / root.tz, metres) over the last SPAN seconds,
// so a horse that stops after a stop move reads "standing", whatever was asked.

export const SPAN = 0.5; // s of frames the speed is measured over
export const STANDING = 0.05; // m/s: below it the horse stands

/** Ground speed (m/s) over `samples` ([t s, x m, z m], oldest first): path length / time; null with < 2. */
export function measuredSpeed(samples) {
  if (samples.length < 2) return null;
  let path = 0;
  for (let k = 1; k < samples.length; k++) {
    path += Math.hypot(samples[k][1] - samples[k - 1][1], samples[k][2] - samples[k - 1][2]);
  }
  const dt = samples[samples.length - 1][0] - samples[0][0];
  return dt > 0 ? path / dt : null;
}

/**
 * One header line and its level (ok / warn): what the horse does now. `status`: the tick's
 * (gait, move); `driver`: the frames' driver; `speed`: measured (m/s) or null.
 */
export function describeHorse(status, driver, speed) {
  if (speed === null || !Number.isFinite(speed)) return ["horse: no frames yet", "warn"];
  const pace = `${speed.toFixed(1)} m/s`;
  const own = driver === "procedural"; // the tick's gait and move describe the procedural horse only
  const move = own && status && status.move ? status.move : null;
  if (move) return [`horse: ${move} · ${pace}`, "ok"];
  if (speed < STANDING) return [`horse: standing · ${pace}`, "warn"];
  const gait = own && status && status.gait ? status.gait : null;
  return [`horse: ${gait ? `${gait} · ` : ""}${pace}`, "ok"];
}

/** Keeps the last SPAN s of root positions and the header element up to date. */
export class HorseNow {
  constructor(element) {
    this.element = element;
    this.samples = [];
    this.status = null;
    this.driver = null;
    this.speed = null;
  }

  /** A frame's time (s) and values (metres, after the page's unit conversion). */
  frame(t, values, driver) {
    this.driver = driver;
    const x = values["root.tx"];
    const z = values["root.tz"];
    if (!Number.isFinite(x) || !Number.isFinite(z)) return;
    if (this.samples.length && t <= this.samples[this.samples.length - 1][0]) this.samples = []; // a new stream
    this.samples.push([t, x, z]);
    while (this.samples.length > 2 && t - this.samples[0][0] > SPAN) this.samples.shift();
  }

  fromStatus(msg) {
    this.status = { gait: msg.gait, move: msg.move };
  }

  /** Repaint (a few times a second: the text is read, not animated). */
  show() {
    this.speed = measuredSpeed(this.samples);
    const [text, level] = describeHorse(this.status, this.driver, this.speed);
    this.element.textContent = text;
    this.element.className = `status ${level}`;
    return text;
  }
}
