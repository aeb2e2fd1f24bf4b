// The rule weights, grouped by rule and equation (GET /api/params/groups; without it,
// by the key's prefix), each with its full name, and a filter that hides what does not
// match (a name, a group or an equation number: "head", "Eq. 12", "12").

const $ = (id) => document.getElementById(id);

/** The smallest equation number a group's title names ("Eq. 10-11: ..." -> 10), or Infinity. */
export function equationOf(title) {
  const m = /Eq\.\s*(\d+)/.exec(title || "");
  return m ? Number(m[1]) : Infinity;
}

function rangeFor(v) {
  if (v === 0) return [-1, 1];
  const a = Math.abs(v);
  return v > 0 ? [0, 3 * a] : [-3 * a, 0];
}

/** `params`: {key: value}; `groups`: [{group, title, keys}] or null. */
export function renderWeights(params, groups, onInput) {
  const box = $("params");
  box.innerHTML = "";
  const numeric = Object.keys(params).filter((k) => typeof params[k] === "number");
  if (!groups) {
    const by = new Map();
    for (const k of numeric) {
      const g = k.split(".")[0];
      if (!by.has(g)) by.set(g, []);
      by.get(g).push(k);
    }
    groups = [...by].map(([group, keys]) => ({ group, title: group, keys }));
  }
  const listed = new Set();
  const sorted = [...groups].sort((a, b) => equationOf(a.title) - equationOf(b.title));
  for (const g of sorted) {
    const keys = g.keys.filter((k) => numeric.includes(k));
    if (!keys.length) continue;
    const details = document.createElement("details");
    details.open = true;
    details.dataset.group = g.group;
    details.dataset.title = g.title;
    const summary = document.createElement("summary");
    summary.textContent = g.title === g.group ? g.group : `${g.title} (${g.group})`;
    details.appendChild(summary);
    for (const key of keys) {
      listed.add(key);
      details.appendChild(slider(key, params[key], onInput));
    }
    box.appendChild(details);
  }
  for (const k of numeric.filter((n) => !listed.has(n))) box.appendChild(slider(k, params[k], onInput));
  filterWeights();
}

function slider(key, value, onInput) {
  const [lo, hi] = rangeFor(value);
  const label = document.createElement("label");
  label.dataset.key = key;
  const name = document.createElement("span");
  name.textContent = key;
  name.title = key;
  const input = document.createElement("input");
  input.type = "range";
  Object.assign(input, { min: lo, max: hi, step: (hi - lo) / 400, value });
  input.dataset.key = key;
  const out = document.createElement("output");
  out.textContent = (+value).toPrecision(3);
  input.addEventListener("input", () => {
    out.textContent = (+input.value).toPrecision(3);
    onInput(key, +input.value);
  });
  label.append(name, input, out);
  return label;
}

/** Hide every weight (and group) the filter does not match; returns how many are shown. */
export function filterWeights() {
  const f = $("param-filter").value.trim().toLowerCase();
  const eq = /^(?:eq\.?\s*)?(\d+)$/.exec(f);
  let shown = 0;
  for (const label of $("params").querySelectorAll("label[data-key]")) {
    const group = label.closest("details");
    const title = group ? group.dataset.title.toLowerCase() : "";
    let match = f === "" || label.dataset.key.toLowerCase().includes(f) || title.includes(f);
    if (eq && group) match = inEquations(group.dataset.title, Number(eq[1]));
    label.hidden = !match;
    if (match) shown += 1;
  }
  for (const g of $("params").querySelectorAll("details[data-group]")) g.hidden = !g.querySelector("label:not([hidden])");
  return shown;
}

/** Whether "Eq. 1-3", "Eq. 14-17", "Eq. 18 and ..." covers equation `n`. */
function inEquations(title, n) {
  const m = /Eq\.\s*(\d+)(?:\s*-\s*(\d+))?/.exec(title || "");
  if (!m) return false;
  const lo = Number(m[1]);
  const hi = m[2] ? Number(m[2]) : lo;
  return n >= lo && n <= hi;
}
