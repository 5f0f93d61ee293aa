// The l3 console: the service's API driven from a browser page. Plain JavaScript, no framework
// and no build step; every request goes to this origin. The bearer token typed into the Token
// field is kept in sessionStorage and sent with every API call (the page itself needs none).
"use strict";

const $ = (sel) => document.querySelector(sel);

/** A DOM element: h("td", { class: "x", onclick: f }, child, "text", …). */
function h(tag, props, ...kids) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(props || {})) {
    if (v == null || v === false) continue;
    if (k === "class") e.className = v;
    else if (k === "text") e.textContent = v;
    else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v === true ? "" : v);
  }
  for (const c of kids.flat()) {
    if (c != null && c !== false) e.append(c instanceof Node ? c : String(c));
  }
  return e;
}

// ---------------------------------------------------------------- the API

const TOKEN_KEY = "l3.console.token";

/** A failed request: a problem document's title and detail, or what went wrong instead. */
class ApiError extends Error {
  constructor(title, detail, status, code) {
    super(detail ? `${title}: ${detail}` : title);
    Object.assign(this, { title, detail, status, code });
  }
}

function withToken(extra) {
  const hs = new Headers(extra || {});
  const t = sessionStorage.getItem(TOKEN_KEY);
  if (t) hs.set("Authorization", "Bearer " + t);
  return hs;
}

/** The ApiError of a failed answer: application/problem+json's title and detail, else its text. */
async function problemOf(resp) {
  const type = resp.headers.get("content-type") || "";
  let title = `${resp.status} ${resp.statusText}`.trim();
  let detail = "";
  let code;
  try {
    if (type.includes("json")) {
      const p = await resp.json();
      title = p.title || title;
      detail = p.detail || "";
      code = p.code;
    } else {
      detail = (await resp.text()).trim().slice(0, 300);
    }
  } catch (_) {
    // an unreadable body: the status says what there is to say
  }
  if (resp.status === 401) {
    detail += (detail ? " " : "") + "Enter the service's bearer token in the Token field above.";
  }
  const after = resp.headers.get("retry-after");
  if (after) detail += ` Try again in ${after} s.`;
  return new ApiError(title, detail, resp.status, code);
}

async function api(method, path, opts = {}) {
  let resp;
  try {
    resp = await fetch(path, { method, headers: withToken(opts.headers), body: opts.body });
  } catch (e) {
    throw new ApiError("The service cannot be reached", e.message);
  }
  if (!resp.ok) throw await problemOf(resp);
  return resp;
}

const getJson = async (path) => (await api("GET", path)).json();

async function sendJson(method, path, body) {
  const resp = await api(method, path, {
    headers: { "Content-Type": "application/json" },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  return resp.status === 204 ? null : resp.json();
}

// ---------------------------------------------------------------- messages and formats

/** Shows a message (a string) or an error (its title in bold, then its detail) in `box`. */
function say(box, what, kind) {
  box.hidden = false;
  box.replaceChildren();
  box.className = "msg " + (kind || (what instanceof Error ? "error" : "ok"));
  if (what instanceof ApiError) {
    box.append(h("strong", { text: what.title }), what.detail ? " " + what.detail : "");
  } else if (what instanceof Error) {
    box.append(h("strong", { text: "Error" }), " " + what.message);
  } else {
    box.textContent = what;
  }
}

function quiet(box) {
  box.hidden = true;
  box.replaceChildren();
}

/** Runs `fn`, showing its error in `box` (the status line's when none is given). */
async function guarded(box, fn) {
  try {
    return await fn();
  } catch (e) {
    say(box || $("#st-detail"), e);
    return undefined;
  }
}

const fmtBytes = (n) =>
  n >= 1 << 20 ? `${(n / (1 << 20)).toFixed(1)} MiB` : n >= 1024 ? `${(n / 1024).toFixed(0)} KiB` : `${n} B`;
const fmtTime = (ms) => (ms ? new Date(ms).toLocaleString() : "—");
const fmtNum = (v, d = 2) => (typeof v === "number" && isFinite(v) ? v.toFixed(d) : "—");
const shortId = (id) => (id ? h("code", { title: id, text: id.length > 16 ? id.slice(0, 16) + "…" : id }) : "—");

const cache = { lights: [], tables: [], activeId: null, sensors: [] };
const blobUrls = {};

/** An object URL for `blob` under `key`, revoking the one it replaces. */
function blobUrl(key, blob) {
  if (blobUrls[key]) URL.revokeObjectURL(blobUrls[key]);
  blobUrls[key] = URL.createObjectURL(blob);
  return blobUrls[key];
}

// ---------------------------------------------------------------- status

function metric(text, name) {
  const esc = name.replace(/[.*+?^${}()|[\]\\]/g, "\\$&");
  const m = text.match(new RegExp("^" + esc + " ([0-9.eE+-]+)$", "m"));
  return m ? Number(m[1]) : null;
}

async function refreshStatus() {
  const pill = $("#st-ready");
  const detail = $("#st-detail");
  let resp;
  try {
    resp = await fetch("/readyz", { headers: withToken() });
  } catch (e) {
    pill.dataset.state = "down";
    pill.textContent = "unreachable";
    say(detail, new ApiError("The service cannot be reached", e.message));
    return;
  }
  // back from being unreachable: the jobs' poll (backing off meanwhile) picks up at once
  if (jobsPoll.failures) loadJobs();
  if (resp.ok) {
    pill.dataset.state = "ready";
    pill.textContent = "ready";
    quiet(detail);
  } else {
    pill.dataset.state = "not-ready";
    pill.textContent = "not ready";
    say(detail, await problemOf(resp));
  }
  await Promise.allSettled([
    getJson("/healthz").then((j) => {
      $("#st-backend").textContent = j.backend || "—";
      $("#st-backend").title = "l3 " + j.version;
    }),
    api("GET", "/metrics")
      .then((r) => r.text())
      .then((text) => {
        const q = metric(text, "l3_render_queue_length");
        $("#st-queue").textContent = q == null ? "—" : `${q} waiting`;
        const run = metric(text, 'l3_training_jobs{state="running"}');
        const queued = metric(text, 'l3_training_jobs{state="queued"}');
        $("#st-jobs").textContent = run == null ? "—" : `${run} running, ${queued} queued`;
      }),
    loadTables(),
  ]);
}

function showActive() {
  const t = cache.tables.find((x) => x.id === cache.activeId);
  $("#st-table").textContent = cache.activeId || "none";
  $("#st-sensor").textContent = t ? t.sensor_name : "—";
  markActiveJobs();
}

// ---------------------------------------------------------------- tabs

const LOADERS = {
  render: () => {},
  tables: () => Promise.allSettled([loadTables(), loadSensors()]),
  jobs: () => loadJobs(),
  evals: () => loadEvals(),
  lights: () => loadLights(),
};

function showTab(name) {
  if (!LOADERS[name]) name = "render";
  for (const b of document.querySelectorAll(".tabs button")) {
    b.setAttribute("aria-selected", String(b.dataset.tab === name));
  }
  for (const p of document.querySelectorAll(".panel")) p.hidden = p.id !== "tab-" + name;
  if (location.hash !== "#" + name) history.replaceState(null, "", "#" + name);
  guarded(null, async () => LOADERS[name]());
}

// ---------------------------------------------------------------- illuminants

/** Fills a light <select>: the registry's names, a colour temperature, and (renders) the file's. */
function fillLightSelect(sel, fromFile, fallback) {
  const keep = sel.value;
  sel.replaceChildren();
  if (fromFile) sel.append(h("option", { value: "" }, "from the file (its metadata, else estimated)"));
  for (const l of cache.lights) {
    sel.append(h("option", { value: l.name }, l.cct ? `${l.name} (${Math.round(l.cct)} K)` : l.name));
  }
  sel.append(h("option", { value: "cct" }, "a colour temperature…"));
  sel.value = keep || fallback;
  if (!sel.value) sel.selectedIndex = 0;
}

/** The light a select and its CCT field name: a registry name, `cct:K`, or "" (the file's). */
function lightOf(sel, cct) {
  if (sel.value !== "cct") return sel.value;
  const k = Number(cct.value);
  if (!(k >= 1000 && k <= 25000)) throw new Error("the colour temperature must be 1000–25000 K");
  return `cct:${Math.round(k)}`;
}

async function loadLights() {
  const j = await getJson("/v1/illuminants");
  cache.lights = j.items;
  fillLightSelect($("#render-light"), true, "");
  fillLightSelect($("#eval-light"), false, "Tungsten");
  const box = $("#job-lights");
  const checked = new Set([...box.querySelectorAll("input:checked")].map((i) => i.value));
  if (!box.children.length) ["D65", "Tungsten"].forEach((n) => checked.add(n));
  box.replaceChildren(
    ...cache.lights.map((l) =>
      h("label", {}, h("input", { type: "checkbox", value: l.name, checked: checked.has(l.name) }), l.name),
    ),
  );
  $("#lights-body").replaceChildren(
    ...cache.lights.map((l) =>
      h(
        "tr",
        {},
        h("td", { class: "name" }, h("strong", { text: l.name })),
        h("td", {}, l.source, l.user_defined ? h("span", { class: "tag", text: "user" }) : null),
        h("td", { text: l.cct ? `${Math.round(l.cct)} K` : "—" }),
        h("td", { class: "mono", text: l.white_xy ? l.white_xy.map((v) => v.toFixed(4)).join(", ") : "—" }),
        h(
          "td",
          {},
          l.deletable
            ? h("button", { class: "small danger", onclick: () => deleteLight(l.name) }, "Remove")
            : null,
        ),
      ),
    ),
  );
}

async function addLight(ev) {
  ev.preventDefault();
  const msg = $("#light-msg");
  quiet(msg);
  const name = $("#light-name").value.trim();
  await guarded(msg, async () => {
    const cct = Number($("#light-cct").value);
    const l = await sendJson("PUT", `/v1/illuminants/${encodeURIComponent(name)}`, { cct });
    say(msg, `Added ${l.name} (${Math.round(l.cct || cct)} K).`);
    await loadLights();
  });
}

async function deleteLight(name) {
  if (!confirm(`Remove the illuminant ${name}?`)) return;
  const msg = $("#light-msg");
  await guarded(msg, async () => {
    await api("DELETE", `/v1/illuminants/${encodeURIComponent(name)}`);
    say(msg, `Removed ${name}.`);
    await loadLights();
  });
}

// ---------------------------------------------------------------- render

const FORMATS = {
  png: { accept: "image/png", ext: "png", shown: true },
  jpeg: { accept: "image/jpeg", ext: "jpg", shown: true },
  ppm: { accept: "image/x-portable-pixmap", ext: "ppm" },
  tiff16: { accept: "image/tiff", ext: "tiff", query: { tiff: "srgb16" } },
  tiff: { accept: "image/tiff", ext: "tiff", query: { tiff: "xyz" } },
  xyz: { accept: "application/octet-stream", ext: "xyz.f32" },
};

const SOURCES = {
  query: "as asked",
  metadata: "from the file's metadata",
  estimated: "estimated from the frame",
  default: "the default, D65",
};

let renderFile = null;

function bodyType(file) {
  const n = file.name.toLowerCase();
  if (n.endsWith(".dng")) return "image/x-adobe-dng";
  if (n.endsWith(".png")) return "image/png";
  if (n.endsWith(".tif") || n.endsWith(".tiff")) return "image/tiff";
  if (n.endsWith(".pgm")) return "image/x-portable-graymap";
  return "application/octet-stream";
}

function setRenderFile(file) {
  renderFile = file || null;
  const text = $("#drop-text");
  if (!file) return;
  const type = bodyType(file);
  text.replaceChildren(h("strong", { text: file.name }), h("br"), h("small", { text: `${fmtBytes(file.size)} · ${type}` }));
  $("#raw-size").hidden = type !== "application/octet-stream";
  $("#render-go").disabled = false;
}

/** The render's query: the light, correction, table, downscale and (raw) the frame's size. */
function renderQuery(file, format) {
  const q = new URLSearchParams(format.query || {});
  const light = lightOf($("#render-light"), $("#render-cct"));
  if (light) q.set("illuminant", light);
  if ($("#render-correction").value) q.set("correction", $("#render-correction").value);
  if ($("#render-table").value) q.set("table", $("#render-table").value);
  if ($("#render-preview").value !== "1") q.set("preview", $("#render-preview").value);
  if (bodyType(file) === "application/octet-stream") {
    const w = $("#render-width").value;
    const hh = $("#render-height").value;
    if (!w || !hh) throw new Error("a raw frame needs its width and height");
    q.set("width", w);
    q.set("height", hh);
    if ($("#render-cfa").value.trim()) q.set("cfa", $("#render-cfa").value.trim());
  }
  return q;
}

async function doRender(ev) {
  ev.preventDefault();
  const file = renderFile;
  const msg = $("#render-msg");
  const button = $("#render-go");
  if (!file) return;
  const format = FORMATS[$("#render-format").value];
  button.disabled = true;
  say(msg, "Rendering…", "info");
  $("#render-result").classList.add("stale"); // the previous render's, until this one is in
  try {
    const q = renderQuery(file, format);
    const post = (accept, query) =>
      api("POST", "/v1/render?" + query, {
        headers: { "Content-Type": bodyType(file), Accept: accept },
        body: file,
      });
    const resp = await post(format.accept, q);
    const blob = await resp.blob();
    showRenderInfo(resp.headers);
    const stem = file.name.replace(/\.[^.]*$/, "");
    const link = $("#render-download");
    link.href = blobUrl("download", blob);
    link.download = `${stem}.${format.ext}`;
    link.textContent = `Download ${link.download} (${fmtBytes(blob.size)})`;
    link.hidden = false;
    let shown = blob;
    let note = "";
    if (!format.shown) {
      // a browser shows neither TIFF, PPM nor float XYZ: the same render as PNG beside it
      q.delete("tiff");
      shown = await (await post("image/png", q)).blob();
      note = `Shown as PNG; the download is the ${$("#render-format").selectedOptions[0].text}.`;
    }
    const img = $("#render-img");
    img.src = blobUrl("shown", shown);
    await img.decode();
    $("#render-note").textContent = note || `${img.naturalWidth} × ${img.naturalHeight} px`;
    $("#render-figure").hidden = false;
    $("#render-empty").hidden = true;
    quiet(msg);
  } catch (e) {
    clearRender();
    say(msg, e);
  } finally {
    button.disabled = false;
    $("#render-result").classList.remove("stale");
  }
}

/** Takes the previous render off the page: its image, its x-l3-* values and its download. */
function clearRender() {
  $("#render-figure").hidden = true;
  $("#render-img").removeAttribute("src");
  $("#render-note").textContent = "";
  $("#render-info").replaceChildren();
  const link = $("#render-download");
  link.hidden = true;
  link.removeAttribute("href");
  for (const key of ["shown", "download"]) {
    if (blobUrls[key]) URL.revokeObjectURL(blobUrls[key]);
    delete blobUrls[key];
  }
  $("#render-empty").textContent = "The render failed: no image (see the message beside the form).";
  $("#render-empty").hidden = false;
}

function showRenderInfo(headers) {
  const get = (n) => headers.get(n);
  const ms = (n) => (get(n) == null ? "—" : `${Number(get(n)).toFixed(1)} ms`);
  const choice = get("x-l3-table-choice");
  const rows = [
    ["Light", "x-l3-illuminant", get("x-l3-illuminant")],
    ["Light from", "x-l3-illuminant-source", SOURCES[get("x-l3-illuminant-source")] || get("x-l3-illuminant-source")],
    ["Correction", "x-l3-correction", get("x-l3-correction")],
    ["Table", "x-l3-table", get("x-l3-table")],
    ["Table chosen", "x-l3-table-choice", choice + (get("x-l3-sensor") ? ` (${get("x-l3-sensor")})` : "")],
    ["Size", "x-l3-width", `${get("x-l3-width")} × ${get("x-l3-height")}`],
    ["Queue", "x-l3-queue-ms", ms("x-l3-queue-ms")],
    ["Decode", "x-l3-decode-ms", ms("x-l3-decode-ms")],
    ["Render", "x-l3-render-ms", ms("x-l3-render-ms")],
    ["Encode", "x-l3-encode-ms", ms("x-l3-encode-ms")],
    ["Saturated px", "x-l3-saturated-pixels", get("x-l3-saturated-pixels")],
    ["Fallback px", "x-l3-fallback-pixels", get("x-l3-fallback-pixels")],
    ["Texture px", "x-l3-texture-pixels", get("x-l3-texture-pixels")],
    ["Clamped px", "x-l3-clamped-pixels", get("x-l3-clamped-pixels")],
  ];
  $("#render-info").replaceChildren(
    ...rows.flatMap(([label, key, value]) => [
      h("dt", { text: label }),
      h("dd", { "data-key": key, text: value == null ? "—" : value }),
    ]),
  );
}

function setupDrop() {
  const drop = $("#drop");
  $("#render-file").addEventListener("change", (e) => setRenderFile(e.target.files[0]));
  drop.addEventListener("dragover", (e) => {
    e.preventDefault();
    drop.classList.add("over");
  });
  drop.addEventListener("dragleave", () => drop.classList.remove("over"));
  drop.addEventListener("drop", (e) => {
    e.preventDefault();
    drop.classList.remove("over");
    if (e.dataTransfer.files.length) setRenderFile(e.dataTransfer.files[0]);
  });
  // a file dropped beside the zone must not replace the page
  window.addEventListener("dragover", (e) => e.preventDefault());
  window.addEventListener("drop", (e) => e.preventDefault());
}

// ---------------------------------------------------------------- tables and sensors

function fillTableSelect(sel) {
  const keep = sel.value;
  const first = sel.options[0];
  sel.replaceChildren(
    first,
    ...cache.tables
      .filter((t) => t.status === "ok")
      .map((t) => h("option", { value: t.id }, `${t.id} · ${t.sensor_name} · ${t.train_illuminants.join("+")}`)),
  );
  sel.value = cache.tables.some((t) => t.id === keep) ? keep : "";
}

let tablesSig = "";

async function loadTables() {
  const j = await getJson("/v1/tables");
  cache.activeId = j.active_table_id;
  showActive();
  const sig = JSON.stringify(j);
  if (sig === tablesSig) return;
  tablesSig = sig;
  cache.tables = j.items;
  showActive();
  fillTableSelect($("#render-table"));
  fillTableSelect($("#eval-table"));
  $("#tables-body").replaceChildren(
    ...cache.tables.map((t) =>
      h(
        "tr",
        { class: t.active ? "active" : null },
        h("td", {}, shortId(t.id), t.active ? h("span", { class: "tag ok", text: "active" }) : null),
        h("td", { text: t.kind }),
        h("td", { text: t.sensor_name }),
        h("td", { class: "name", text: t.train_illuminants.join(", ") }),
        h("td", { text: fmtTime(t.created_at_ms) }),
        h("td", { text: fmtBytes(t.size_bytes) }),
        h("td", {}, t.status === "ok" ? "ok" : h("span", { class: "tag bad", title: t.status_detail || "", text: t.status })),
        h(
          "td",
          {},
          h("button", { class: "small", disabled: t.active || t.status !== "ok", onclick: () => activate(t.id) }, "Activate"),
          " ",
          h("a", { class: "small", href: `/v1/tables/${t.id}/download`, download: `${t.id}.safetensors` }, "Download"),
          " ",
          h("button", { class: "small", disabled: t.status !== "ok", onclick: () => evaluateTable(t.id) }, "Evaluate"),
        ),
      ),
    ),
  );
}

async function activate(id) {
  const msg = $("#tables-msg");
  await guarded(msg, async () => {
    await api("POST", `/v1/tables/${id}/activate`);
    say(msg, `${id} is now the active table.`);
    await refreshStatus();
  });
}

function evaluateTable(id) {
  showTab("evals");
  $("#eval-table").value = id;
}

async function loadSensors() {
  const j = await getJson("/v1/sensors");
  cache.sensors = j.items;
  const sel = $("#job-sensor");
  const keep = sel.value || "paper_default";
  sel.replaceChildren(
    h("option", { value: "paper_default" }, "paper_default (the paper's RGBW sensor)"),
    ...j.items.map((s) => h("option", { value: s.name }, `${s.name} (${s.cfa})`)),
  );
  sel.value = keep;
  $("#sensors-body").replaceChildren(
    ...j.items.map((s) =>
      h(
        "tr",
        {},
        h("td", {}, h("strong", { text: s.name })),
        h("td", { class: "mono", text: s.cfa }),
        h("td", { text: s.source }),
        h("td", { text: [s.make, s.model].filter(Boolean).join(" ") || "—" }),
        h("td", {}, s.table_id ? shortId(s.table_id) : "not trained"),
        h("td", {}, h("button", { class: "small", onclick: () => trainFor(s.name) }, "Train…")),
      ),
    ),
  );
}

function trainFor(name) {
  showTab("jobs");
  $("#job-sensor").value = name;
}

// ---------------------------------------------------------------- training jobs

/** A number field's value, or undefined when it is empty (the service's default). */
function numberField(sel) {
  const v = $(sel).value.trim();
  if (v === "") return undefined;
  const n = Number(v);
  if (!Number.isFinite(n)) throw new Error(`${sel.slice(1)} is not a number`);
  return n;
}

async function submitJob(ev) {
  ev.preventDefault();
  const msg = $("#job-msg");
  quiet(msg);
  await guarded(msg, async () => {
    const illuminants = [...document.querySelectorAll("#job-lights input:checked")].map((i) => i.value);
    if (!illuminants.length) throw new Error("choose at least one illuminant");
    const body = {
      sensor: $("#job-sensor").value || "paper_default",
      kind: $("#job-kind").value,
      illuminants,
      scenes: numberField("#job-scenes"),
      scene_size: numberField("#job-scene-size"),
      levels: numberField("#job-levels"),
      patch_size: numberField("#job-patch"),
      chroma_classes: numberField("#job-chroma"),
      seed: numberField("#job-seed"),
      shards: numberField("#job-shards"),
      activate: $("#job-activate").checked,
    };
    const job = await sendJson("POST", "/v1/training-jobs", body);
    say(msg, `Job ${job.id} queued.`);
    await loadJobs();
  });
}

const ONE_PIECE = ["queued", "starting", "survey", "accumulate", "solve", "done"];
const SHARDED = ["queued", "survey", "accumulate", "merge"];
const ACTIVE = new Set(["queued", "running"]);
// The list is polled every second while a job runs (and the tab shows), else every 5 s, so jobs
// submitted elsewhere appear; while the service cannot be reached, the last jobs stay on screen
// marked stale and the poll backs off (2, 4, 8 … 30 s) until it answers again.
const JOBS_BUSY_MS = 1000;
const JOBS_IDLE_MS = 5000;
const jobsPoll = { timer: null, seq: 0, failures: 0, shown: null, cards: new Map(), status: new Map() };

async function loadJobs() {
  clearTimeout(jobsPoll.timer);
  const seq = ++jobsPoll.seq;
  let delay;
  try {
    const list = await getJson("/v1/training-jobs?limit=20");
    // a running job's own description carries its shards
    const jobs = await Promise.all(
      list.items.map((j) => (ACTIVE.has(j.status) ? getJson(`/v1/training-jobs/${j.id}`).catch(() => j) : j)),
    );
    if (seq !== jobsPoll.seq) return; // a newer load took over (and set the timer)
    jobsPoll.failures = 0;
    jobsPoll.shown = Date.now();
    quiet($("#jobs-msg"));
    $("#jobs-list").classList.remove("stale");
    // a job that ended may have made or activated a table: the header, the tables and the cards follow
    const ended = jobs.some((j) => !ACTIVE.has(j.status) && ACTIVE.has(jobsPoll.status.get(j.id)));
    jobsPoll.status = new Map(jobs.map((j) => [j.id, j.status]));
    drawJobs(jobs);
    const busy = jobs.some((j) => ACTIVE.has(j.status));
    delay = busy && !$("#tab-jobs").hidden ? JOBS_BUSY_MS : JOBS_IDLE_MS;
    if (ended || jobs.some((j) => j.table_id && !cache.tables.some((t) => t.id === j.table_id))) {
      refreshStatus();
    }
  } catch (e) {
    if (seq !== jobsPoll.seq) return;
    jobsPoll.failures += 1;
    delay = Math.min(30000, 1000 * 2 ** jobsPoll.failures);
    const box = $("#jobs-msg");
    say(box, e);
    const when = jobsPoll.shown
      ? `Showing the jobs as of ${new Date(jobsPoll.shown).toLocaleTimeString()}`
      : "No jobs loaded yet";
    box.append(h("br"), h("small", { text: `${when}; trying again in ${delay / 1000} s.` }));
    if (jobsPoll.shown) $("#jobs-list").classList.add("stale");
  }
  jobsPoll.timer = setTimeout(loadJobs, delay);
}

function bar(fraction, label) {
  const fill = h("div");
  const b = h("div", { class: "bar", role: "progressbar", "aria-valuemin": 0, "aria-valuemax": 100, "aria-label": label }, fill);
  setBar(b, fraction);
  return b;
}

function setBar(b, fraction) {
  const pct = Math.round(Math.min(1, Math.max(0, fraction || 0)) * 100);
  b.setAttribute("aria-valuenow", pct);
  b.firstChild.style.width = `${pct}%`; // through the CSSOM: the page's CSP allows no inline style
}

/** Sets `el`'s text only when it changed (a node replaced under a pointer or focus loses it). */
function setText(el, text) {
  if (el.textContent !== text) el.textContent = text;
}

function drawStages(box, job) {
  const order = job.shards ? SHARDED : ONE_PIECE;
  const now = order.indexOf(job.stage);
  const finished = job.status === "succeeded";
  const sig = `${order.join()}|${now}|${finished}`;
  if (box.dataset.sig === sig) return;
  box.dataset.sig = sig;
  box.replaceChildren(
    ...order.map((s, i) =>
      h("span", { class: finished || (now >= 0 && i < now) ? "done" : i === now ? "now" : null, text: s }),
    ),
  );
}

function drawShards(box, job) {
  box.hidden = !job.shards;
  if (!job.shards) return;
  const items = job.shards.items;
  const label = (s) => `${s.stage} ${s.shard}/${job.shards.count}` + (s.attempts > 1 ? ` · attempt ${s.attempts}` : "");
  if (box.children.length !== items.length * 2) {
    box.replaceChildren(...items.flatMap((s) => [h("span"), bar(0, `${s.stage} shard ${s.shard}`)]));
  }
  items.forEach((s, i) => {
    setText(box.children[2 * i], label(s));
    setBar(box.children[2 * i + 1], s.status === "succeeded" ? 1 : s.progress);
  });
}

/** What a job trains: its sensor (a design's name), kind, lights and scenes. */
function jobWhat(job) {
  const req = job.request || {};
  const design = typeof req.sensor === "object" && req.sensor;
  return [
    design ? (design.name ? `${design.name} (a sensor design)` : "a sensor design") : req.sensor || "paper_default",
    req.kind || "si",
    (req.illuminants || ["D65", "Tungsten"]).join("+"),
    req.scenes ? `${req.scenes} scenes of ${req.scene_size || 96} px` : null,
  ]
    .filter(Boolean)
    .join(" · ");
}

/** A job's card, built once: its parts are updated in place by updateCard at every poll. */
function jobCard(job) {
  const p = {};
  p.tag = h("span", { class: "tag" });
  p.what = h("span", { class: "grow sub" });
  p.cancel = h("button", { class: "small danger", onclick: () => cancelJob(job.id, p) }, "Cancel");
  p.bar = bar(0, `job ${job.id}`);
  p.pct = h("span", { class: "pct" });
  p.stage = h("span");
  p.attempt = h("span", { class: "attempt" });
  p.stages = h("div", { class: "stages" });
  p.shards = h("div", { class: "shards" });
  p.error = h("p", { class: "msg error" });
  p.tableId = h("span");
  p.activeTag = h("span", { class: "tag ok", text: "active" });
  p.activate = h("button", { class: "small", onclick: () => activateFromCard(p) }, "Activate");
  p.table = h(
    "div",
    { class: "sub table" },
    "table ",
    p.tableId,
    p.activeTag,
    " ",
    h("button", { class: "small", onclick: () => evaluateTable(p.job.table_id) }, "Evaluate"),
    " ",
    p.activate,
  );
  p.msg = h("p", { class: "msg", hidden: true, "aria-live": "polite" });
  p.card = h(
    "div",
    { class: "job", "data-id": job.id },
    h("header", {}, shortId(job.id), p.tag, p.what, p.cancel),
    p.bar,
    h("div", { class: "sub" }, p.pct, p.stage, p.attempt),
    p.stages,
    p.shards,
    p.error,
    p.table,
    p.msg,
  );
  updateCard(p, job);
  return p;
}

function updateCard(p, job) {
  p.job = job;
  const fraction = job.status === "succeeded" ? 1 : job.progress;
  p.card.dataset.status = job.status;
  setText(p.tag, job.status);
  p.tag.className = "tag" + (job.status === "succeeded" ? " ok" : job.status === "failed" ? " bad" : "");
  setText(p.what, jobWhat(job));
  p.cancel.hidden = !ACTIVE.has(job.status);
  if (p.said === "cancel" && !ACTIVE.has(job.status)) quietCard(p); // its status tag says the rest
  setBar(p.bar, fraction);
  setText(p.pct, `${Math.round(fraction * 100)} %`);
  const secs = job.timings && job.timings.running_ms != null ? ` · ${(job.timings.running_ms / 1000).toFixed(1)} s` : "";
  setText(p.stage, ` · ${job.stage || job.status}${secs}`);
  // a restart re-queues a running job, which starts again from 0 %
  const attempts = job.attempts || 0;
  p.attempt.hidden = attempts <= 1;
  setText(p.attempt, attempts > 1 ? ` · attempt ${attempts} (restarted)` : "");
  p.attempt.title = attempts > 1 ? "the service restarted while the job ran; it started again from the beginning" : "";
  drawStages(p.stages, job);
  drawShards(p.shards, job);
  p.error.hidden = !job.error;
  setText(p.error, job.error || "");
  p.table.hidden = !job.table_id;
  if (job.table_id && p.tableId.dataset.id !== job.table_id) {
    p.tableId.dataset.id = job.table_id;
    p.tableId.replaceChildren(shortId(job.table_id));
  }
  markActive(p);
}

/** The card's table marked active, or not, as the header says. */
function markActive(p) {
  const active = !!p.job.table_id && p.job.table_id === cache.activeId;
  p.activeTag.hidden = !active;
  p.activate.disabled = active || p.busy;
  if (p.said === "activate" && !active && !p.busy) quietCard(p); // another table is active since
}

function quietCard(p) {
  p.said = null;
  quiet(p.msg);
}

function drawJobs(jobs) {
  const box = $("#jobs-list");
  const cards = jobsPoll.cards;
  const seen = new Set(jobs.map((j) => j.id));
  for (const [id, p] of cards) {
    if (!seen.has(id)) {
      p.card.remove();
      cards.delete(id);
    }
  }
  if (!jobs.length) {
    box.replaceChildren(h("p", { class: "empty", text: "No jobs yet." }));
    return;
  }
  const empty = box.querySelector(":scope > .empty");
  if (empty) empty.remove();
  // cards stay the same elements, moved only when out of place, so focus and clicks survive
  jobs.forEach((job, i) => {
    let p = cards.get(job.id);
    if (p) updateCard(p, job);
    else cards.set(job.id, (p = jobCard(job)));
    if (box.children[i] !== p.card) box.insertBefore(p.card, box.children[i] || null);
  });
}

function markActiveJobs() {
  for (const p of jobsPoll.cards.values()) markActive(p);
}

async function activateFromCard(p) {
  const id = p.job.table_id;
  p.busy = true;
  markActive(p);
  say(p.msg, `Activating ${id}…`, "info");
  try {
    await api("POST", `/v1/tables/${id}/activate`);
    await refreshStatus();
    say(p.msg, `${id} is now the active table.`);
    p.said = "activate";
  } catch (e) {
    p.said = null;
    say(p.msg, e);
  } finally {
    p.busy = false;
    markActive(p);
  }
}

async function cancelJob(id, p) {
  await guarded(p.msg, async () => {
    await api("POST", `/v1/training-jobs/${id}/cancel`);
    say(p.msg, `Cancelling ${id}.`);
    p.said = "cancel";
    await loadJobs();
  });
}

// ---------------------------------------------------------------- evaluations

async function runEval(ev) {
  ev.preventDefault();
  const msg = $("#eval-msg");
  const button = $("#eval-go");
  quiet(msg);
  button.disabled = true;
  await guarded(msg, async () => {
    const body = {
      method: $("#eval-method").value,
      acquisition_illuminant: lightOf($("#eval-light"), $("#eval-cct")),
      seed: numberField("#eval-seed"),
      noise: $("#eval-noise").checked,
      exposure_factor: numberField("#eval-exposure"),
    };
    if ($("#eval-table").value) body.table_id = $("#eval-table").value;
    say(msg, "Evaluating on a simulated Natural-100 chart…", "info");
    const e = await sendJson("POST", "/v1/evaluations", body);
    quiet(msg);
    await showEval(e);
    await loadEvals();
  });
  button.disabled = false;
}

async function showEval(e) {
  const r = e.report || {};
  const s = r.summary || {};
  const req = e.request || {};
  $("#eval-empty").hidden = true;
  $("#eval-view").hidden = false;
  $("#eval-title").textContent = `${e.method} on ${e.chart} under ${e.acquisition_illuminant}`;
  const rows = [
    ["Evaluation", e.id],
    ["Table", e.table_id || "—"],
    ["Mean ΔE2000", fmtNum(s.mean)],
    ["90th percentile", fmtNum(s.p90)],
    ["Max", fmtNum(s.max)],
    ["Exposure", req.exposure_factor != null ? `× ${req.exposure_factor}` : "auto"],
  ];
  if (r.s_cielab_mean != null) rows.push(["S-CIELAB", fmtNum(r.s_cielab_mean)]);
  if (r.mtf50 != null) rows.push(["MTF50", `${fmtNum(r.mtf50, 3)} cy/px`]);
  if (r.false_colour != null) rows.push(["False colour", fmtNum(r.false_colour)]);
  $("#eval-info").replaceChildren(...rows.flatMap(([k, v]) => [h("dt", { text: k }), h("dd", { text: v })]));
  $("#eval-json").href = `/v1/evaluations/${e.id}`;
  const img = $("#eval-figure");
  img.removeAttribute("src");
  const resp = await api("GET", `/v1/evaluations/${e.id}`, { headers: { Accept: "image/svg+xml" } });
  img.src = blobUrl("figure", await resp.blob());
  await img.decode();
}

async function openEval(id) {
  await guarded($("#eval-msg"), async () => showEval(await getJson(`/v1/evaluations/${id}`)));
}

async function loadEvals() {
  const j = await getJson("/v1/evaluations");
  $("#evals-body").replaceChildren(
    ...j.items.map((e) =>
      h(
        "tr",
        {},
        h("td", {}, shortId(e.id)),
        h("td", { text: e.method }),
        h("td", {}, shortId(e.table_id)),
        h("td", { class: "name", text: e.acquisition_illuminant }),
        h("td", { text: e.request && e.request.exposure_factor != null ? `× ${e.request.exposure_factor}` : "auto" }),
        h("td", { text: fmtNum(e.mean_delta_e) }),
        h("td", { text: fmtTime(e.created_at_ms) }),
        h("td", {}, h("button", { class: "small", onclick: () => openEval(e.id) }, "Open")),
      ),
    ),
  );
}

// ---------------------------------------------------------------- start

function init() {
  const token = $("#token");
  token.value = sessionStorage.getItem(TOKEN_KEY) || "";
  token.addEventListener("input", () => {
    if (token.value.trim()) sessionStorage.setItem(TOKEN_KEY, token.value.trim());
    else sessionStorage.removeItem(TOKEN_KEY);
  });
  for (const b of document.querySelectorAll(".tabs button")) {
    b.addEventListener("click", () => showTab(b.dataset.tab));
  }
  for (const b of document.querySelectorAll("[data-refresh]")) {
    b.addEventListener("click", () => guarded(null, async () => LOADERS[b.dataset.refresh]()));
  }
  $("#render-light").addEventListener("change", (e) => ($("#render-cct-row").hidden = e.target.value !== "cct"));
  $("#eval-light").addEventListener("change", (e) => ($("#eval-cct-row").hidden = e.target.value !== "cct"));
  $("#render-form").addEventListener("submit", doRender);
  $("#job-form").addEventListener("submit", submitJob);
  $("#eval-form").addEventListener("submit", runEval);
  $("#light-form").addEventListener("submit", addLight);
  // each submit attempt starts without the last one's message, even one the browser's own
  // validation stops (the invalid event fires then, instead of submit)
  for (const form of document.querySelectorAll("form")) {
    const box = form.querySelector(".msg");
    form.addEventListener("invalid", () => quiet(box), true);
  }
  setupDrop();
  showTab(location.hash.slice(1));
  guarded(null, () => Promise.all([loadLights(), loadSensors(), loadJobs(), loadEvals()]));
  refreshStatus();
  setInterval(refreshStatus, 5000);
}

init();
