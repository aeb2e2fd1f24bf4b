// The /ws/rider connection: hello, subscribe, frames, status; reconnects by itself.
// Protocol: docs/protocol.md. Unknown message types and fields are ignored.

export class RiderLink {
  /**
   * @param {string} url ws:// URL of /ws/rider
   * @param {object} on callbacks: hello(msg), frame(frame), status(msg), state(name, why)
   */
  constructor(url, on, rate = 120, token = null) {
    this.token = token;
    this.url = url;
    this.on = on;
    this.rate = rate;
    this.state = "connecting";
    this.session = null;
    this.riderNames = [];
    this.horseNames = [];
    this.retry = 250;
    this.ws = null;
    this.frames = 0;
    this.restarts = 0;
    this.subscription = {}; // more subscribe fields (panels: e.g. {saddle: true})
    this.connect();
  }

  setState(state, why = "") {
    if (this.state === state && state !== "gone") return;
    this.state = state;
    this.on.state(state, why);
  }

  connect() {
    let ws;
    try {
      // The token (if any) travels as a subprotocol: browsers cannot set headers here.
      const protocols = ["riderlive.v1", ...(this.token ? [`riderlive.token.${this.token}`] : [])];
      ws = new WebSocket(this.url, protocols);
    } catch (err) {
      this.scheduleReconnect(String(err));
      return;
    }
    this.ws = ws;
    if (this.state !== "gone") this.setState("connecting"); // once gone, say so until a hello arrives
    ws.onmessage = (ev) => {
      if (typeof ev.data !== "string") return;
      let msg;
      try {
        msg = JSON.parse(ev.data);
      } catch {
        return;
      }
      this.handle(msg);
    };
    ws.onclose = (ev) => {
      if (this.ws !== ws) return;
      this.ws = null;
      this.scheduleReconnect(ev.reason || `closed (${ev.code})`);
    };
    ws.onerror = () => {};
  }

  scheduleReconnect(why) {
    this.setState("gone", why);
    const delay = this.retry;
    this.retry = Math.min(this.retry * 2, 4000);
    setTimeout(() => this.connect(), delay);
  }

  handle(msg) {
    switch (msg.type) {
      case "hello": {
        if (this.session && msg.session !== this.session) this.restarts += 1;
        this.session = msg.session;
        this.retry = 250;
        this.riderNames = (msg.channels || []).map((c) => c.name);
        const horse = (msg.horse_channels || []).map((c) => c.name);
        this.horseNames = [];
        this.tickRate = msg.tick_rate;
        this.on.hello(msg);
        const rate = Math.min(this.rate, msg.tick_rate || this.rate);
        // The rider parts (reins, stirrups) come by subscription only, listed apart.
        this.parts = (msg.rider_part_channels || []).map((c) => c.name);
        const sub = { type: "subscribe", horse_channels: horse, rate, ...this.subscription };
        if (this.parts.length) sub.channels = [...new Set([...this.riderNames, ...this.parts])];
        this.send(sub);
        this.setState("live");
        break;
      }
      case "subscribed":
        this.riderNames = msg.channels || this.riderNames;
        this.horseNames = msg.horse_channels || [];
        this.rateNow = msg.rate;
        break;
      case "frame":
        this.frames += 1;
        this.on.frame(this.toFrame(msg));
        break;
      case "status":
        this.on.status(msg);
        break;
      case "goodbye":
        this.setState("gone", `service stopped: ${msg.reason || "goodbye"}`);
        break;
      default:
        break;
    }
  }

  /** A frame as {seq, t, sourceT, driver, values: {name: value}, saddle, estimate, tc (timecode label)}. */
  toFrame(msg) {
    const values = {};
    const put = (names, list) => {
      if (Array.isArray(list)) for (let i = 0; i < names.length && i < list.length; i++) values[names[i]] = list[i];
      else if (list && typeof list === "object") Object.assign(values, list);
    };
    put(this.riderNames, msg.values);
    put(this.horseNames, msg.horse);
    return { seq: msg.seq, t: msg.t, sourceT: msg.source_t, driver: msg.driver, values, saddle: msg.saddle, estimate: msg.estimate, tc: msg.tc };
  }

  send(obj) {
    if (this.ws && this.ws.readyState === WebSocket.OPEN) this.ws.send(JSON.stringify(obj));
  }
}
