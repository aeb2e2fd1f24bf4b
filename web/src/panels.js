// Side panels and page events, for the page's own parts and for new ones (saddle,
// platform, latency...): a panel module gets a box and subscribes to what it needs.
//
//   import { addPanel, on } from "./panels.js";
//   export function mountSaddle(page) {
//     const box = addPanel("saddle", "Saddle estimate");
//     on("frame", (frame) => { ... });          // also "hello", "status", "state"
//   }
//
// and one line in main.js: `mountSaddle(page);`.

const listeners = new Map();

/** Call `fn(payload)` on every `event`: "hello", "frame", "status", "state" (connection). */
export function on(event, fn) {
  if (!listeners.has(event)) listeners.set(event, []);
  listeners.get(event).push(fn);
}

/** Tell the listeners; one that throws is reported on the page and never stops the others. */
export function emit(event, payload) {
  for (const fn of listeners.get(event) || []) {
    try {
      fn(payload);
    } catch (err) {
      const page = window.riderlive;
      if (page && page.errors) page.errors.push(`${event} listener: ${err}`);
    }
  }
}

/** A collapsible panel at the end of the side bar; returns its body element. */
export function addPanel(id, title, { open = true } = {}) {
  const details = document.createElement("details");
  details.id = `panel-${id}`;
  details.open = open;
  const summary = document.createElement("summary");
  summary.textContent = title;
  const body = document.createElement("div");
  body.className = "panel-body";
  details.append(summary, body);
  document.getElementById("panels").appendChild(details);
  return body;
}
