// "Fit a preset" in the take browser (docs/fit.md, "On the page"). A take with a reference
// rider (uploaded: PUT /api/takes/NAME/reference; or the rider it recorded) gets a "fit"
// button; the fit (POST /api/takes/NAME/fit) writes a preset into the service's preset
// directory and answers with the report, shown here as two compact tables (per channel r
// and RMS; per parameter value, uncertainty, identified or not). "apply" loads the preset
// with PUT /api/preset: the tick blends to it as to any preset change. "⬆ rider" uploads
// a rider file (CSV, JSONL, Parquet, or BVH read with the default bone map).

import { controlToken } from "./controls.js";

const $ = (id) => document.getElementById(id);
const FORMATS = { csv: "csv", jsonl: "jsonl", ndjson: "jsonl", parquet: "parquet", pq: "parquet", bvh: "bvh" };

/** A preset name from a take's (the service's name pattern: 1-64 of A-Z a-z 0-9 _ -). */
export function presetNameFor(take) {
  const base = `${take}-fit`.replace(/[^A-Za-z0-9_-]/g, "_").replace(/^[^A-Za-z0-9]+/, "");
  return (base || "fit").slice(0, 64);
}

const fixed = (v, digits) => (v === null || v === undefined ? "–" : Number(v).toFixed(digits));
const short = (v) => (v === null || v === undefined ? "–" : Math.abs(v) >= 1e4 || (v !== 0 && Math.abs(v) < 1e-3) ? Number(v).toExponential(2) : Number(v).toPrecision(4));

function table(head, rows, cls) {
  const t = document.createElement("table");
  t.className = cls;
  const tr = t.createTHead().insertRow();
  for (const h of head) tr.appendChild(Object.assign(document.createElement("th"), { textContent: h }));
  const body = t.createTBody();
  for (const row of rows) {
    const r = body.insertRow();
    for (const cell of row.cells) r.insertCell().textContent = cell;
    if (row.cls) r.className = row.cls;
  }
  return t;
}

export class FitPanel {
  /** `api`, `attempt`: the page's REST helpers; `refresh()`: redraw the take list (a reference changed). */
  constructor(api, attempt, refresh) {
    this.api = api;
    this.attempt = attempt;
    this.refresh = refresh;
    this.last = null; // the last report shown (tests read it)
    this.panel = document.createElement("div");
    this.panel.id = "fit-panel";
    this.panel.hidden = true;
    $("takes").after(this.panel);
  }

  /** The buttons of one take row: "fit" when it has a reference rider; always "⬆ rider". */
  buttons(take) {
    const out = [];
    if (take.reference) {
      const b = Object.assign(document.createElement("button"), { textContent: "fit", className: "take-fit" });
      b.title = `fit a preset to this take's ${take.reference} reference rider`;
      b.addEventListener("click", () => this.open(take));
      out.push(b);
    }
    const up = Object.assign(document.createElement("button"), { textContent: "⬆ rider", className: "take-upload" });
    up.title = "import a reference rider for this take (CSV, JSONL, Parquet of rider channels, or a BVH)";
    up.addEventListener("click", () => this.pick(take.name));
    out.push(up);
    return out;
  }

  pick(name) {
    const input = Object.assign(document.createElement("input"), { type: "file", accept: ".csv,.jsonl,.ndjson,.parquet,.pq,.bvh" });
    input.addEventListener("change", () => input.files[0] && this.upload(name, input.files[0]));
    input.click();
  }

  async upload(name, file) {
    const format = FORMATS[file.name.split(".").pop().toLowerCase()];
    if (!format) return this.attempt(`rider for ${name}`, async () => { throw new Error(`${file.name}: use .csv, .jsonl, .parquet or .bvh`); });
    const out = await this.attempt(`rider for ${name}`, () => this.put(`/api/takes/${encodeURIComponent(name)}/reference?format=${format}`, file));
    if (out) await this.refresh();
    return out;
  }

  async put(path, blob) {
    // The raw file as the body (the page's api() sends JSON): the same token header.
    const headers = { "content-type": "application/octet-stream" };
    const token = controlToken();
    if (token) headers.authorization = `Bearer ${token}`;
    const res = await fetch(path, { method: "PUT", headers, body: blob });
    const data = await res.json().catch(() => null);
    if (!res.ok) throw new Error(`PUT ${path}: ${res.status} ${data && data.detail ? JSON.stringify(data.detail) : ""}`);
    return data;
  }

  open(take) {
    const p = this.panel;
    p.hidden = false;
    p.innerHTML = "";
    p.dataset.take = take.name;
    const title = Object.assign(document.createElement("div"), { className: "fit-title", textContent: `fit a preset to ${take.name} (${take.reference} rider)` });
    const row = Object.assign(document.createElement("div"), { className: "row" });
    const name = Object.assign(document.createElement("input"), { id: "fit-name", value: presetNameFor(take.name), maxLength: 64, title: "the new preset's name" });
    const drift = Object.assign(document.createElement("input"), { type: "checkbox", id: "fit-drift" });
    const driftLabel = Object.assign(document.createElement("label"), { title: "take out translation offsets and trends (mocap drift)" });
    driftLabel.append(drift, " drift");
    const go = Object.assign(document.createElement("button"), { id: "fit-run", textContent: "fit" });
    const close = Object.assign(document.createElement("button"), { textContent: "✕", title: "close" });
    close.addEventListener("click", () => { p.hidden = true; });
    const status = Object.assign(document.createElement("span"), { id: "fit-status", className: "muted" });
    const report = Object.assign(document.createElement("div"), { id: "fit-report" });
    go.addEventListener("click", () => this.run(take.name, name.value, drift.checked, go, status, report));
    row.append(name, driftLabel, go, close, status);
    p.append(title, row, report);
  }

  async run(take, preset, drift, go, status, report) {
    go.disabled = true;
    status.textContent = "fitting… (seconds to a minute)";
    report.innerHTML = "";
    const fit = (overwrite) => this.api("POST", `/api/takes/${encodeURIComponent(take)}/fit`, { preset, drift, overwrite });
    const out = await this.attempt(`fit ${take}`, async () => {
      try {
        return await fit(false);
      } catch (err) {
        // A preset of that name exists (perhaps a hand-written one): replace it only when confirmed.
        if (/ 409 .*exists/.test(err.message) && confirm(`replace the preset ${preset}?`)) return fit(true);
        throw err;
      }
    });
    go.disabled = false;
    status.textContent = out ? "" : "the fit failed: see the message below";
    if (out && out.fit) this.show(out.fit, report);
  }

  show(fit, report) {
    this.last = fit;
    const params = fit.parameters || [];
    const identified = params.filter((p) => p.identified).length;
    const summary = Object.assign(document.createElement("div"), { className: "fit-summary" });
    const take = (fit.takes || [])[0] || {};
    summary.textContent = `${fit.preset}: ${identified} of ${params.length} numbers identified · clock offset ${fixed((take.offset_s || 0) * 1000, 1)} ms · ${take.frames_used || 0} frames · ${fixed(fit.seconds, 1)} s`;
    const channels = table(
      ["channel", "r", "RMS"],
      (take.channels || []).map((c) => ({ cells: [c.channel, fixed(c.r, 4), `${short(c.rms)} ${c.unit === "attribute" ? "" : c.unit}`] })),
      "fit-channels",
    );
    const rows = params.map((p) => ({
      cells: [p.name, short(p.value), p.uncertainty === null ? "–" : `± ${short(p.uncertainty)}`, p.identified ? "identified" : p.status.replaceAll("_", " ")],
      cls: p.identified ? "fit-identified" : "fit-held",
    }));
    const parameters = table(["parameter", "value", "±", ""], rows, "fit-params");
    const apply = Object.assign(document.createElement("button"), { id: "fit-apply", textContent: `apply ${fit.preset}` });
    apply.title = "load it as the preset (blended in like any preset change)";
    apply.addEventListener("click", () => this.apply(fit.preset));
    const notes = Object.assign(document.createElement("div"), { className: "muted fit-notes", textContent: (fit.notes || []).join(" · ") });
    report.append(summary, apply, channels, parameters, notes);
  }

  async apply(name) {
    const out = await this.attempt(`apply ${name}`, () => this.api("PUT", "/api/preset", { name }));
    const select = $("preset");
    if (out && select) {
      if (![...select.options].some((o) => o.value === name)) select.appendChild(new Option(name, name));
      select.value = name;
    }
    return out;
  }
}
