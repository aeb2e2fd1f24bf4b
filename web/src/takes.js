// The take browser: the takes directory (GET /api/takes), newest first, with replay,
// bake (POST /api/takes/NAME/bake: the rules as set now, over the take's horse) and
// download of the take and of its bake (fetched with the token, saved as a file).

const $ = (id) => document.getElementById(id);

function duration(t, rate) {
  if (!t.rows || !rate) return "";
  const s = t.rows / rate;
  return s >= 60 ? `${Math.floor(s / 60)} min ${Math.round(s % 60)} s` : `${s.toFixed(1)} s`;
}

export class Takes {
  /** `rate()`: the tick rate (Hz) takes are recorded at, for their durations. */
  constructor(api, attempt, replay, rate) {
    this.rate = rate;
    this.api = api;
    this.attempt = attempt;
    this.replay = replay;
    this.shown = null;
    this.baked = new Set();
    this.fit = null; // FitPanel (fit.js): a row's "fit" and "⬆ rider" buttons
  }

  async download(path, filename) {
    const out = await this.attempt(`download ${filename}`, () => this.api("GET", path, undefined, "blob"));
    if (!out) return;
    const a = document.createElement("a");
    a.href = URL.createObjectURL(out);
    a.download = filename;
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 10000);
  }

  async bake(name, li) {
    li.querySelector(".take-info").textContent = "baking…";
    const out = await this.attempt(`bake ${name}`, () => this.api("POST", `/api/takes/${encodeURIComponent(name)}/bake`, {}));
    if (out && out.bake) {
      this.baked.add(name);
      // The list may have been redrawn meanwhile (the take's rows changed): update the row shown now.
      const row = [...$("takes").children].find((el) => el.dataset.take === name) || li;
      row.querySelector(".take-baked").hidden = false;
      row.querySelector(".take-info").textContent = `baked ${out.bake.rows} rows with ${out.bake.preset}`;
    }
  }

  /** Redraw the list when it changed; returns the names. */
  async refresh() {
    let takes;
    try {
      takes = (await this.api("GET", "/api/takes")).takes || [];
    } catch {
      return null;
    }
    const key = JSON.stringify(takes.map((t) => [t.name, t.rows, t.complete, t.reference]));
    if (key === this.shown) return takes.map((t) => t.name);
    this.shown = key;
    const ul = $("takes");
    ul.innerHTML = "";
    for (const t of takes) {
      const li = document.createElement("li");
      li.dataset.take = t.name;
      const name = document.createElement("span");
      name.className = "take-name";
      name.textContent = t.name;
      const buttons = document.createElement("span");
      const button = (text, title, cls, fn) => {
        const b = document.createElement("button");
        b.textContent = text;
        b.title = title;
        b.className = cls;
        b.addEventListener("click", fn);
        buttons.appendChild(b);
        return b;
      };
      button("▶", "replay this take", "take-replay", () => this.replay(t.name));
      button("bake", "run the rules as set now over this take's horse", "take-bake", () => this.bake(t.name, li));
      button("⬇ take", "download the take as recorded", "take-download", () => this.download(`/api/takes/${encodeURIComponent(t.name)}/file`, `${t.name}.csv`));
      const baked = button("⬇ rider", "download the last bake", "take-baked", () => this.download(`/api/takes/${encodeURIComponent(t.name)}/baked`, `${t.name}.rider.csv`));
      baked.hidden = !this.baked.has(t.name);
      if (this.fit) buttons.append(...this.fit.buttons(t));
      const info = document.createElement("span");
      info.className = "take-info";
      const when = t.modified ? new Date(t.modified * 1000).toLocaleString() : "";
      info.textContent = [duration(t, this.rate()), t.rows ? `${t.rows} rows` : "", t.complete === false ? "incomplete" : "", when].filter(Boolean).join(" · ");
      li.append(name, buttons, info);
      ul.appendChild(li);
    }
    const sel = $("src-take");
    const cur = sel.value;
    sel.innerHTML = "";
    for (const t of takes) sel.appendChild(new Option(t.name, t.name));
    if (takes.some((t) => t.name === cur)) sel.value = cur;
    return takes.map((t) => t.name);
  }
}
