// calib web app. Every call goes to the Calibration and Simulator APIs over HTTP JSON
// (/api/v1/<Method>, the RPC's request and answer messages); plots are SVG drawn by the
// server's plotting code (/ui/...). No framework, no build step.
"use strict";

const PHASES = { 0: "unknown", 1: "running", 2: "finished", 3: "failed", 4: "cancelled" };
const BEST_TOLERANCE = 0.01; // a run within 1% of the best objective has reached it

const app = {
  model: null,        // ModelDescription of the chosen model
  fmus: {},           // uploaded FMUs' models by name: {id, model: ModelDescription}
  dataset: null,      // Dataset answered by UploadDataset (with file_name)
  campaignId: null,   // the campaign shown on the Calibration tab
  campaign: null,     // its CampaignState
  history: [],        // [{evaluations, run_best}] while it is watched
  watching: null,     // AbortController of the watch
  plotting: false,
  plotDue: false,
  started: false,     // the tabs' contents are loaded (after the login, if one is asked)
  experiments: [],    // further records: {key, prefix, dataset, card, fixed}
  nextExperiment: 0,  // key of the next experiment added
};

const $ = (id) => document.getElementById(id);

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k === "text") node.textContent = v;
    else if (v !== undefined && v !== null && v !== false) node.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children) node.append(c);
  return node;
}

function fmt(v, digits = 6) {
  if (v === null || v === undefined || !Number.isFinite(v)) return "—";
  if (v === 0) return "0";
  const a = Math.abs(v);
  const rounded = Number(v.toPrecision(digits));
  return a >= 1e-3 && a < 1e6 ? String(rounded) : rounded.toExponential();
}

function showError(id, message) {
  const box = $(id);
  if (message) {
    box.textContent = message;
    box.hidden = false;
  } else {
    box.textContent = "";
    box.hidden = true;
  }
}

// ---- the APIs ---------------------------------------------------------------------------

async function call(method, request, init = {}) {
  const response = await fetch(`/api/v1/${method}`, {
    method: "POST",
    headers: init.headers || { "Content-Type": "application/json" },
    body: init.body !== undefined ? init.body : JSON.stringify(request || {}),
  });
  const text = await response.text();
  let answer;
  try { answer = JSON.parse(text); } catch { answer = { message: text }; }
  if (response.status === 401) showLogin();
  if (!response.ok) throw new Error(answer.message || `${method}: HTTP ${response.status}`);
  return answer;
}

// A server stream (Server-Sent Events, one whole state each) until it ends.
async function follow(url, onState, signal) {
  const response = await fetch(url, { signal });
  if (response.status === 401) showLogin();
  if (!response.ok) {
    const text = await response.text();
    let message = text;
    try { message = JSON.parse(text).message; } catch { /* plain text */ }
    throw new Error(message);
  }
  const reader = response.body.getReader();
  const decoder = new TextDecoder();
  let buffer = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffer += decoder.decode(value, { stream: true });
    let cut;
    while ((cut = buffer.indexOf("\n\n")) >= 0) {
      const block = buffer.slice(0, cut);
      buffer = buffer.slice(cut + 2);
      let event = "message";
      const data = [];
      for (const line of block.split("\n")) {
        if (line.startsWith("event:")) event = line.slice(6).trim();
        else if (line.startsWith("data:")) data.push(line.slice(5).replace(/^ /, ""));
      }
      if (!data.length) continue; // keep-alive comment
      if (event === "error") throw new Error(data.join("\n"));
      onState(JSON.parse(data.join("\n")));
    }
  }
}

// SVG text in a figure, scaled to its column.
function figure(svgText, caption) {
  const fig = el("figure", { class: "plot" });
  const holder = el("div", { role: "img", "aria-label": caption });
  holder.innerHTML = svgText;
  const svg = holder.querySelector("svg");
  if (svg && !svg.getAttribute("viewBox")) {
    const w = parseFloat(svg.getAttribute("width")), h = parseFloat(svg.getAttribute("height"));
    if (w && h) svg.setAttribute("viewBox", `0 0 ${w} ${h}`);
    svg.removeAttribute("width");
    svg.removeAttribute("height");
  }
  fig.append(holder, el("figcaption", { text: caption }));
  return fig;
}

async function plot(request) {
  const response = await fetch("/ui/plot", {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify(request),
  });
  const text = await response.text();
  if (response.status === 401) showLogin();
  if (!response.ok) throw new Error(JSON.parse(text).message);
  return text;
}

// ---- the login --------------------------------------------------------------------------
// A server with a token (calib coordinator --token-file) asks for it once: POST /login
// with it as the bearer token answers with a session cookie (HttpOnly, SameSite=Strict)
// that every later call carries. The page never keeps the token.

function showLogin() {
  document.body.classList.add("signing-in");
  $("login").hidden = false;
  $("login-token").focus();
}

async function signIn(event) {
  event.preventDefault();
  const input = $("login-token");
  $("login-submit").disabled = true;
  try {
    const response = await fetch("/login", {
      method: "POST",
      headers: { Authorization: `Bearer ${input.value.trim()}` },
    });
    if (!response.ok) {
      const text = await response.text();
      let message = text;
      try { message = JSON.parse(text).message; } catch { /* plain text */ }
      showError("login-error", message || `HTTP ${response.status}`);
      return;
    }
    input.value = "";
    showError("login-error", "");
    $("login").hidden = true;
    document.body.classList.remove("signing-in");
    if (!app.started) begin();
  } finally {
    $("login-submit").disabled = false;
  }
}

// Load what the tabs show, once signed in (at once on a server without a token).
async function begin() {
  let state = { required: false, signed_in: true };
  try { state = await (await fetch("/login")).json(); } catch { /* an older server */ }
  if (state.required && !state.signed_in) {
    showLogin();
    return;
  }
  app.started = true;
  loadModels();
  refreshCampaigns();
}

// ---- tabs -------------------------------------------------------------------------------

function selectTab(tab, focus = false) {
  for (const t of document.querySelectorAll('[role="tab"]')) {
    const on = t === tab;
    t.setAttribute("aria-selected", String(on));
    t.tabIndex = on ? 0 : -1;
    $(t.getAttribute("aria-controls")).hidden = !on;
  }
  if (focus) tab.focus();
  if (tab.id === "tab-diagnosis") refreshCampaigns();
}

function setUpTabs() {
  const tabs = [...document.querySelectorAll('[role="tab"]')];
  for (const [i, tab] of tabs.entries()) {
    tab.addEventListener("click", () => selectTab(tab));
    tab.addEventListener("keydown", (e) => {
      const step = { ArrowRight: 1, ArrowLeft: -1 }[e.key];
      if (step) {
        e.preventDefault();
        selectTab(tabs[(i + step + tabs.length) % tabs.length], true);
      } else if (e.key === "Home") {
        selectTab(tabs[0], true);
      } else if (e.key === "End") {
        selectTab(tabs[tabs.length - 1], true);
      }
    });
  }
}

// ---- Model tab --------------------------------------------------------------------------

async function loadModels() {
  try {
    const { models } = await call("ListModels", {});
    const select = $("model-select");
    for (const m of models) select.append(el("option", { value: m.name, text: m.name }));
    select.addEventListener("change", () => describe(select.value));
    if (models.length) await describe(models[0].name);
  } catch (e) {
    showError("model-error", e.message);
  }
}

// An FMU chosen with the file picker or dropped on the Model tab: uploaded (UploadFmu),
// its models added to the list, the default one shown.
async function uploadFmu(file) {
  showError("model-error", "");
  if (!file) return;
  $("fmu-status").textContent = `uploading ${file.name}…`;
  try {
    const fmu = await call(`UploadFmu?file_name=${encodeURIComponent(file.name)}`, null, {
      headers: { "Content-Type": "application/octet-stream" },
      body: await file.arrayBuffer(),
    });
    const select = $("model-select");
    for (const m of fmu.models) {
      app.fmus[m.name] = { id: fmu.id, model: m };
      if (![...select.options].some((o) => o.value === m.name)) {
        select.append(el("option", { value: m.name, text: `${m.name} (${fmu.file_name})` }));
      }
    }
    const first = fmu.models[0];
    select.value = first.name;
    await describe(first.name);
    $("fmu-status").textContent =
      `${fmu.file_name}: FMU ${fmu.id.slice(0, 12)}…, ${first.parameters.length} parameters, ` +
      `${first.outputs.length} outputs; models ${fmu.models.map((m) => m.name).join(", ")}`;
  } catch (e) {
    $("fmu-status").textContent = "";
    showError("model-error", e.message);
  }
}

function setUpFmuDrop() {
  const zone = $("fmu-drop");
  $("fmu-file").addEventListener("change", (e) => uploadFmu(e.target.files[0]));
  zone.addEventListener("dragover", (e) => { e.preventDefault(); zone.classList.add("over"); });
  zone.addEventListener("dragleave", () => zone.classList.remove("over"));
  zone.addEventListener("drop", (e) => {
    e.preventDefault();
    zone.classList.remove("over");
    uploadFmu(e.dataTransfer.files[0]);
  });
}

// The FMU hash of an uploaded FMU's model, as the Simulator's `fmu_hash` bytes.
function fmuHash(name) {
  const fmu = app.fmus[name];
  if (!fmu) return undefined;
  return fmu.id.match(/../g).map((h) => parseInt(h, 16));
}

// A bound as a form value: empty when the model gives none (JSON null for ±infinity).
const bound = (v) => (Number.isFinite(v) ? String(v) : "");

async function describe(name) {
  showError("model-error", "");
  const model = app.fmus[name] ? app.fmus[name].model : (await call("Describe", { model: name })).model;
  app.model = model;
  $("model-description").textContent = `${model.name} (version ${model.version}): ${model.description}`;
  const body = $("model-parameters").tBodies[0];
  body.replaceChildren();
  for (const p of model.parameters) {
    const input = el("input", {
      type: "number", step: "any", value: String(p.default_value),
      id: `value-${p.name}`, "aria-label": `value of ${p.name} [${p.unit}]`,
      min: bound(p.min), max: bound(p.max),
    });
    input.addEventListener("change", renderCalibration);
    body.append(el("tr", {},
      el("th", { scope: "row", text: p.name }),
      el("td", {}, input),
      el("td", { text: p.unit }),
      el("td", { class: "num", text: fmt(p.default_value, 8) }),
      el("td", { text: `[${fmt(p.min)}, ${fmt(p.max)}]` }),
      el("td", { text: p.description })));
  }
  const outputs = $("model-outputs").querySelector(".choices");
  outputs.replaceChildren();
  for (const [i, o] of model.outputs.entries()) {
    outputs.append(el("label", {},
      el("input", { type: "checkbox", name: "model-output", value: o.name, checked: i < 2 }),
      `${o.name} [${o.unit}]`));
  }
  $("model-plots").replaceChildren();
  renderCalibration();
}

// The model's inputs on the Model tab: each left at the model's own value, or driven by a
// column of the uploaded measurement (ids `drive-<name>`, `drive-interp-<name>`).
function renderModelInputs() {
  const body = $("model-inputs").tBodies[0];
  // Every uploaded record's columns: the measurement's, then each experiment's.
  const records = [app.dataset, ...app.experiments.map((x) => x.dataset)].filter((d) => d);
  const choices = records.flatMap((d) => d.columns.map((c) => [`${d.id}/${c}`, `${c} (${d.file_name})`]));
  const note = records.length ? "" : " (upload a measurement to drive it)";
  const kept = {};
  for (const row of body.rows) {
    const [column, interp] = row.querySelectorAll("select");
    kept[row.dataset.input] = [column.value, interp.value];
  }
  body.replaceChildren();
  for (const i of modelInputs()) {
    const column = el("select", { id: `drive-${i.name}`, "aria-label": `signal driving ${i.name} in the simulation` },
      el("option", { value: "", text: `— its own value${note}` }));
    for (const [value, text] of choices) column.append(el("option", { value, text }));
    const interp = el("select", { id: `drive-interp-${i.name}`, "aria-label": `interpolation of ${i.name} in the simulation` });
    for (const [value, text] of INTERPOLATIONS) interp.append(el("option", { value, text }));
    const old = kept[i.name];
    if (old) {
      if (choices.some(([value]) => value === old[0])) column.value = old[0];
      interp.value = old[1];
    }
    const row = el("tr", {}, el("th", { scope: "row", text: `${i.name} [${i.unit}]`, title: i.description }),
      el("td", {}, column), el("td", {}, interp));
    row.dataset.input = i.name;
    body.append(row);
  }
  $("model-inputs").hidden = !modelInputs().length;
}

// A column of an uploaded record with its times (`key`: "<dataset id>/<column>"), fetched
// once.
const columnCache = {};
async function datasetColumn(key) {
  if (!columnCache[key]) {
    const cut = key.indexOf("/");
    const id = key.slice(0, cut), column = key.slice(cut + 1);
    const response = await fetch(`/ui/datasets/${id}/column/${encodeURIComponent(column)}`);
    const text = await response.text();
    if (response.status === 401) showLogin();
    if (!response.ok) throw new Error(JSON.parse(text).message);
    columnCache[key] = JSON.parse(text);
  }
  return columnCache[key];
}

// At most `n` points of a series, for drawing.
function thin(x, y, n = 20000) {
  const step = Math.max(1, Math.ceil(x.length / n));
  if (step === 1) return [x, y];
  return [x.filter((_, k) => k % step === 0), y.filter((_, k) => k % step === 0)];
}

function modelValue(p) {
  const v = parseFloat($(`value-${p.name}`).value);
  return Number.isFinite(v) ? v : p.default_value;
}

async function simulate() {
  showError("model-error", "");
  const model = app.model;
  const stop = parseFloat($("model-stop").value), step = parseFloat($("model-step").value);
  if (!(stop > 0 && step > 0) || stop / step > 200000) {
    showError("model-error", "stop time and step: both positive, at most 200,000 steps");
    return;
  }
  const times = [];
  for (let i = 0; i * step <= stop * (1 + 1e-12); i++) times.push(i * step);
  const outputs = [...document.querySelectorAll('input[name="model-output"]:checked')].map((i) => i.value);
  if (!outputs.length) { showError("model-error", "pick at least one output to plot"); return; }
  const parameters = model.parameters
    .filter((p) => modelValue(p) !== p.default_value)
    .map((p) => ({ name: p.name, value: modelValue(p) }));
  $("model-status").textContent = "simulating…";
  try {
    // Inputs driven by measured columns: the whole column, read as the campaign reads it.
    const driven = [];
    for (const i of modelInputs()) {
      const key = $(`drive-${i.name}`) && $(`drive-${i.name}`).value;
      if (!key) continue;
      const signal = await datasetColumn(key);
      const column = key.slice(key.indexOf("/") + 1);
      const hold = $(`drive-interp-${i.name}`).value === "hold";
      driven.push({ input: i, column, hold, signal });
    }
    const inputs = driven.map((d) => ({
      input: d.input.name, times: d.signal.times, values: d.signal.values, interpolation: d.hold ? 1 : 0,
    }));
    const answer = await call("Simulate", {
      protocol_version: 1, model: model.name, parameters, times, outputs, fmu_hash: fmuHash(model.name), inputs,
    });
    if (answer.failure) throw new Error(`simulation failed: ${answer.failure.message}`);
    const plots = $("model-plots");
    plots.replaceChildren();
    for (const d of driven) {
      const [x, y] = thin(d.signal.times, d.signal.values);
      const svg = await plot({
        title: `${model.name}: input ${d.input.name}`, x_label: "time [s]", y_label: `${d.input.name} [${d.input.unit}]`,
        series: [{ label: `${d.column} (${d.hold ? "held" : "linear"})`, x, y }],
      });
      plots.append(figure(svg, `input ${d.input.name} driven by ${d.column}`));
    }
    for (const s of answer.series) {
      const unit = (model.outputs.find((o) => o.name === s.output) || {}).unit || "";
      const svg = await plot({
        title: `${model.name}: ${s.output}`, x_label: "time [s]", y_label: `${s.output} [${unit}]`,
        series: [{ label: "simulated", x: answer.times, y: s.values }],
      });
      plots.append(figure(svg, `${s.output} simulated over ${fmt(stop)} s`));
    }
    const st = answer.statistics || {};
    $("model-status").textContent = `simulated ${fmt(stop)} s: ${st.accepted_steps} steps, ${st.events} events`;
  } catch (e) {
    $("model-status").textContent = "";
    showError("model-error", e.message);
  }
}

// ---- Measurement tab --------------------------------------------------------------------

async function upload() {
  showError("measurement-error", "");
  const file = $("measurement-file").files[0];
  if (!file) { showError("measurement-error", "choose a file first"); return; }
  const time = $("measurement-time").value.trim() || "time";
  $("measurement-status").textContent = `uploading ${file.name}…`;
  try {
    const query = `file_name=${encodeURIComponent(file.name)}&time_column=${encodeURIComponent(time)}`;
    const dataset = await call(`UploadDataset?${query}`, null, {
      headers: { "Content-Type": "application/octet-stream" },
      body: await file.arrayBuffer(),
    });
    dataset.file_name = file.name;
    app.dataset = dataset;
    $("measurement-status").textContent =
      `${file.name}: ${dataset.samples} samples from ${fmt(dataset.start_time)} s to ${fmt(dataset.stop_time)} s; ` +
      `columns ${dataset.columns.join(", ")}`;
    const box = $("measurement-columns").querySelector(".choices");
    box.replaceChildren();
    for (const c of dataset.columns) {
      box.append(el("label", {}, el("input", { type: "checkbox", name: "measured-column", value: c, checked: true }), c));
    }
    $("measurement-columns").hidden = false;
    $("window-start").value = String(dataset.start_time);
    $("window-stop").value = String(dataset.stop_time);
    renderCalibration();
    plotColumns();
  } catch (e) {
    app.dataset = null;
    $("measurement-status").textContent = "";
    $("measurement-columns").hidden = true;
    $("measurement-plots").replaceChildren();
    showError("measurement-error", e.message);
    renderCalibration();
  }
}

function plotColumns() {
  const plots = $("measurement-plots");
  plots.replaceChildren();
  for (const input of document.querySelectorAll('input[name="measured-column"]:checked')) {
    const c = input.value;
    const img = el("img", {
      src: `/ui/datasets/${app.dataset.id}/plot/${encodeURIComponent(c)}`,
      alt: `plot of the measured column ${c} over time`,
    });
    plots.append(el("figure", { class: "plot" }, img, el("figcaption", { text: `measured ${c}` })));
  }
}

// ---- Calibration tab --------------------------------------------------------------------

function renderCalibration() {
  const model = app.model, dataset = app.dataset;
  $("calibration-context").textContent =
    `Model ${model ? model.name : "(choose one on the Model tab)"}; measurement ` +
    (dataset ? `${dataset.file_name} (${dataset.samples} samples)` : "(upload one on the Measurement tab)");
  if (!model) return;
  const outputs = $("output-map").tBodies[0];
  const keep = {};
  for (const row of outputs.rows) keep[row.dataset.output] = row;
  outputs.replaceChildren();
  for (const o of model.outputs) {
    const old = keep[o.name];
    const column = el("select", { id: `measured-${o.name}`, "aria-label": `measured column for ${o.name}` },
      el("option", { value: "", text: "—" }));
    for (const c of dataset ? dataset.columns : []) column.append(el("option", { value: c, text: c }));
    const fit = el("input", { type: "checkbox", id: `fit-${o.name}`, "aria-label": `fit ${o.name}` });
    const weight = el("input", { type: "number", step: "any", min: "0", value: "1", id: `weight-${o.name}`, "aria-label": `weight of ${o.name}` });
    const scale = el("select", { id: `scale-${o.name}`, "aria-label": `scaling of ${o.name}` },
      el("option", { value: "none", text: "none" }), el("option", { value: "variance", text: "by the measured variance" }));
    if (old) {
      fit.checked = old.querySelector(`#fit-${CSS.escape(o.name)}`).checked;
      const was = old.querySelector("select").value;
      if ([...column.options].some((x) => x.value === was)) column.value = was;
      weight.value = old.querySelector('input[type="number"]').value;
      scale.value = old.querySelectorAll("select")[1].value;
    }
    column.addEventListener("change", () => { fit.checked = column.value !== ""; });
    const row = el("tr", {}, el("td", {}, fit), el("th", { scope: "row", text: `${o.name} [${o.unit}]` }),
      el("td", {}, column), el("td", {}, weight), el("td", {}, scale));
    row.dataset.output = o.name;
    outputs.append(row);
  }
  const params = $("parameter-pick").tBodies[0];
  const kept = {};
  for (const row of params.rows) kept[row.dataset.parameter] = row;
  params.replaceChildren();
  for (const p of model.parameters) {
    const old = kept[p.name];
    const free = el("input", { type: "checkbox", id: `free-${p.name}`, "aria-label": `calibrate ${p.name}` });
    const num = (id, value, label) => el("input", { type: "number", step: "any", id, value: String(value), "aria-label": label });
    const nominal = num(`nominal-${p.name}`, modelValue(p), `nominal ${p.name}`);
    const min = num(`min-${p.name}`, bound(p.min), `min ${p.name}`);
    const max = num(`max-${p.name}`, bound(p.max), `max ${p.name}`);
    const scale = el("select", { id: `pscale-${p.name}`, "aria-label": `scale of ${p.name}` },
      el("option", { value: "lin", text: "lin" }), el("option", { value: "log10", text: "log10" }));
    if (old) {
      free.checked = old.querySelector("input").checked;
      const inputs = old.querySelectorAll('input[type="number"]');
      nominal.value = inputs[0].value; min.value = inputs[1].value; max.value = inputs[2].value;
      scale.value = old.querySelector("select").value;
    }
    const row = el("tr", {}, el("td", {}, free), el("th", { scope: "row", text: `${p.name} [${p.unit}]` }),
      el("td", {}, nominal), el("td", {}, min), el("td", {}, max), el("td", {}, scale));
    row.dataset.parameter = p.name;
    params.append(row);
  }
  inputRows($("input-map").tBodies[0], "", dataset ? dataset.columns : [], "");
  $("input-map").hidden = !modelInputs().length;
  renderExperiments();
}

// ---- inputs and experiments -------------------------------------------------------------

const INTERPOLATIONS = [["linear", "linear"], ["hold", "held (zero-order hold)"]];

const modelInputs = () => (app.model && app.model.inputs) || [];

// A row per model input in `body`: the measured column driving it (ids `<prefix>input-<name>`)
// and how it is read between samples (`<prefix>interp-<name>`), keeping what the rows held.
function inputRows(body, prefix, columns, whose) {
  const kept = {};
  for (const row of body.rows) {
    const [column, interp] = row.querySelectorAll("select");
    kept[row.dataset.input] = [column.value, interp.value];
  }
  body.replaceChildren();
  for (const i of modelInputs()) {
    const column = el("select", { id: `${prefix}input-${i.name}`, "aria-label": `measured column driving ${i.name}${whose}` },
      el("option", { value: "", text: "— (not driven)" }));
    for (const c of columns) column.append(el("option", { value: c, text: c }));
    const interp = el("select", { id: `${prefix}interp-${i.name}`, "aria-label": `interpolation of ${i.name}${whose}` });
    for (const [value, text] of INTERPOLATIONS) interp.append(el("option", { value, text }));
    const old = kept[i.name];
    if (old) {
      if (columns.includes(old[0])) column.value = old[0];
      interp.value = old[1];
    }
    const row = el("tr", {}, el("th", { scope: "row", text: `${i.name} [${i.unit}]`, title: i.description }),
      el("td", {}, column), el("td", {}, interp));
    row.dataset.input = i.name;
    body.append(row);
  }
}

// The Input messages of the rows `<prefix>input-...` that name a column.
function inputMessages(prefix) {
  return modelInputs()
    .filter((i) => $(`${prefix}input-${i.name}`) && $(`${prefix}input-${i.name}`).value)
    .map((i) => ({
      model: i.name, measured: $(`${prefix}input-${i.name}`).value,
      interpolation: $(`${prefix}interp-${i.name}`).value,
    }));
}

function addExperiment() {
  const key = app.nextExperiment++;
  const x = `x${key}-`;
  const n = app.experiments.length + 2;
  const field = (text, attrs) => el("label", {}, text, el("input", attrs));
  const uploadButton = el("button", { type: "button", id: `${x}upload`, text: "Upload" });
  const remove = el("button", { type: "button", text: "Remove", class: "secondary", "aria-label": `remove experiment ${n}` });
  const addFixed = el("button", { type: "button", id: `${x}add-fixed`, text: "Fix a start value" });
  const card = el("fieldset", { class: "experiment", id: `experiment-${key}` },
    el("legend", { text: `Experiment ${n}` }),
    el("div", { class: "row" },
      field("Name", { type: "text", id: `${x}name`, value: `record${n}` }),
      field("File (CSV, or MAT)", { type: "file", id: `${x}file`, accept: ".csv,.txt,.mat" }),
      field("Time column", { type: "text", id: `${x}time`, value: $("measurement-time").value.trim() || "time" }),
      uploadButton, remove),
    el("p", { id: `${x}status`, role: "status", "aria-live": "polite" }),
    el("div", { id: `${x}error`, class: "error", role: "alert", hidden: true }),
    el("div", { class: "row" },
      field("Window start [s]", { type: "number", step: "any", id: `${x}window-start` }),
      field("Window stop [s]", { type: "number", step: "any", id: `${x}window-stop` })),
    el("table", { id: `${x}fixed` },
      el("caption", { text: "Start values for this experiment alone" }),
      el("thead", {}, el("tr", {}, el("th", { scope: "col", text: "parameter" }), el("th", { scope: "col", text: "value" }),
        el("th", { scope: "col" }, el("span", { class: "visually-hidden", text: "remove" })))),
      el("tbody")),
    el("p", {}, addFixed),
    el("table", { id: `${x}inputs` },
      el("caption", { text: "Inputs driven by this record" }),
      el("thead", {}, el("tr", {}, el("th", { scope: "col", text: "model input" }),
        el("th", { scope: "col", text: "measured column" }), el("th", { scope: "col", text: "between samples" }))),
      el("tbody")));
  const experiment = { key, prefix: x, dataset: null, card, fixed: 0 };
  uploadButton.addEventListener("click", () => uploadExperiment(experiment));
  addFixed.addEventListener("click", () => addFixedValue(experiment));
  remove.addEventListener("click", () => {
    app.experiments = app.experiments.filter((e) => e !== experiment);
    card.remove();
    renderExperiments();
  });
  app.experiments.push(experiment);
  $("experiment-list").append(card);
  renderExperiments();
  $(`${x}name`).focus();
}

// A row fixing one model parameter for this experiment alone.
function addFixedValue(experiment) {
  const j = experiment.fixed++;
  const id = `${experiment.prefix}fixed-${j}`;
  const name = el("select", { id: `${id}-name`, "aria-label": `parameter fixed in experiment ${experimentName(experiment)}` });
  for (const p of app.model ? app.model.parameters : []) name.append(el("option", { value: p.name, text: `${p.name} [${p.unit}]` }));
  const value = el("input", { type: "number", step: "any", id: `${id}-value`, "aria-label": "its value" });
  const fill = () => {
    const p = app.model.parameters.find((q) => q.name === name.value);
    if (p) value.value = String(modelValue(p));
  };
  name.addEventListener("change", fill);
  fill();
  const remove = el("button", { type: "button", text: "Remove", "aria-label": "remove this start value" });
  const row = el("tr", {}, el("td", {}, name), el("td", {}, value), el("td", {}, remove));
  row.dataset.fixed = id;
  remove.addEventListener("click", () => row.remove());
  $(`${experiment.prefix}fixed`).tBodies[0].append(row);
  name.focus();
}

function experimentName(experiment) {
  const box = $(`${experiment.prefix}name`);
  return box ? box.value.trim() : "";
}

// The experiments' cards follow the model (its inputs and parameters) and the first record.
function renderExperiments() {
  renderModelInputs();
  const several = app.experiments.length > 0;
  $("first-experiment").hidden = !several;
  for (const [k, x] of app.experiments.entries()) {
    x.card.querySelector("legend").textContent = `Experiment ${k + 2}`;
    const table = $(`${x.prefix}inputs`);
    inputRows(table.tBodies[0], x.prefix, x.dataset ? x.dataset.columns : [], ` in experiment ${k + 2}`);
    table.hidden = !modelInputs().length;
    for (const row of $(`${x.prefix}fixed`).tBodies[0].rows) {
      const select = row.querySelector("select");
      const was = select.value;
      select.replaceChildren();
      for (const p of app.model ? app.model.parameters : []) select.append(el("option", { value: p.name, text: `${p.name} [${p.unit}]` }));
      if ([...select.options].some((o) => o.value === was)) select.value = was;
    }
  }
}

async function uploadExperiment(experiment) {
  const x = experiment.prefix;
  showError(`${x}error`, "");
  const file = $(`${x}file`).files[0];
  if (!file) { showError(`${x}error`, "choose a file first"); return; }
  const time = $(`${x}time`).value.trim() || "time";
  $(`${x}status`).textContent = `uploading ${file.name}…`;
  try {
    const query = `file_name=${encodeURIComponent(file.name)}&time_column=${encodeURIComponent(time)}`;
    const dataset = await call(`UploadDataset?${query}`, null, {
      headers: { "Content-Type": "application/octet-stream" },
      body: await file.arrayBuffer(),
    });
    dataset.file_name = file.name;
    experiment.dataset = dataset;
    $(`${x}status`).textContent =
      `${file.name}: ${dataset.samples} samples from ${fmt(dataset.start_time)} s to ${fmt(dataset.stop_time)} s; ` +
      `columns ${dataset.columns.join(", ")}`;
    $(`${x}window-start`).value = String(dataset.start_time);
    $(`${x}window-stop`).value = String(dataset.stop_time);
    renderExperiments();
  } catch (e) {
    experiment.dataset = null;
    $(`${x}status`).textContent = "";
    showError(`${x}error`, e.message);
    renderExperiments();
  }
}

function number(id) {
  const v = parseFloat($(id).value);
  if (!Number.isFinite(v)) throw new Error(`${$(id).getAttribute("aria-label") || id}: not a number`);
  return v;
}

// The Campaign message of the form: field for field a campaign file.
function campaignMessage() {
  const model = app.model, dataset = app.dataset;
  if (!model) throw new Error("choose a model on the Model tab");
  if (!dataset) throw new Error("upload a measurement on the Measurement tab");
  const outputs = model.outputs
    .filter((o) => $(`fit-${o.name}`).checked)
    .map((o) => {
      const measured = $(`measured-${o.name}`).value;
      if (!measured) throw new Error(`${o.name}: pick the measured column it is compared with`);
      return { model: o.name, measured, weight: number(`weight-${o.name}`), scale: $(`scale-${o.name}`).value };
    });
  const free = model.parameters.filter((p) => $(`free-${p.name}`).checked);
  const parameters = free.map((p) => ({
    name: p.name, nominal: number(`nominal-${p.name}`), min: number(`min-${p.name}`),
    max: number(`max-${p.name}`), scale: $(`pscale-${p.name}`).value,
  }));
  const fixed = {};
  for (const p of model.parameters) {
    if (!free.includes(p) && modelValue(p) !== p.default_value) fixed[p.name] = modelValue(p);
  }
  const methods = [...document.querySelectorAll('input[name="method"]:checked')].map((m) => m.value);
  const windowStop = number("window-stop");
  const inputs = inputMessages("");
  const message = {
    name: $("campaign-name").value.trim(),
    model: model.name,
    fmu_id: app.fmus[model.name] ? app.fmus[model.name].id : "",
    stop_time: windowStop,
    model_parameters: fixed,
    dataset_id: dataset.id,
    outputs,
    inputs,
    parameters,
    window_start: number("window-start"),
    window_stop: windowStop,
    search: {
      methods,
      starts: Math.round(number("starts")),
      max_evaluations: Math.round(number("max-evaluations")),
      seed: Math.round(number("seed")),
    },
  };
  if (!app.experiments.length) return message;
  // Several records: the first is the experiment of the fields above, each card another.
  const experiments = [{
    name: $("experiment-name").value.trim(), dataset_id: dataset.id,
    windows: [{ start: message.window_start, stop: windowStop }], inputs,
  }];
  for (const [k, x] of app.experiments.entries()) {
    const name = experimentName(x) || `experiment ${k + 2}`;
    if (!x.dataset) throw new Error(`experiment ${name}: upload its record first`);
    const own = {};
    for (const row of $(`${x.prefix}fixed`).tBodies[0].rows) {
      own[row.querySelector("select").value] = number(`${row.dataset.fixed}-value`);
    }
    experiments.push({
      name, dataset_id: x.dataset.id,
      windows: [{ start: number(`${x.prefix}window-start`), stop: number(`${x.prefix}window-stop`) }],
      fixed: own, inputs: inputMessages(x.prefix),
    });
  }
  return { ...message, dataset_id: "", window_start: 0, window_stop: 0, inputs: [], experiments };
}

async function start() {
  showError("calibration-error", "");
  let campaign;
  try { campaign = campaignMessage(); } catch (e) { showError("calibration-error", e.message); return; }
  try {
    const { id, started } = await call("SubmitCampaign", { campaign });
    $("calibration-status").textContent = started ? "started" : "known already: showing it";
    watch(id);
  } catch (e) {
    showError("calibration-error", e.message);
  }
}

function runsAtBest(runBest) {
  const finite = runBest.filter((v) => Number.isFinite(v));
  if (!finite.length) return [0, runBest.length];
  const best = Math.min(...finite);
  const threshold = best + BEST_TOLERANCE * Math.abs(best);
  return [finite.filter((v) => v <= threshold).length, runBest.length];
}

function describeState(s) {
  const runBest = (s.run_best || []).map((v) => (v === null ? Infinity : v));
  const [k, n] = runsAtBest(runBest);
  let text = `${s.name}: ${PHASES[s.phase] || s.phase}, ${s.evaluations} evaluations, best objective ${fmt(s.best_objective)}`;
  if (n) text += `, ${k} of ${n} runs at the best`;
  if (s.failure) text += ` (${s.failure})`;
  return text;
}

function watch(id) {
  if (app.watching) app.watching.abort();
  app.campaignId = id;
  app.history = [];
  $("result").hidden = true;
  clearProfiles();
  $("progress-plot").replaceChildren();
  $("cancel").disabled = false;
  $("start").disabled = true;
  const controller = new AbortController();
  app.watching = controller;
  follow(`/api/v1/WatchCampaign/${id}`, (s) => {
    app.campaign = s;
    $("calibration-status").textContent = describeState(s);
    if (s.phase === 1 || app.history.length) {
      app.history.push({ evaluations: s.evaluations, run_best: s.run_best || [] });
      drawProgress();
    }
    if (s.phase !== 1) finish(s);
  }, controller.signal).catch((e) => {
    if (e.name !== "AbortError") showError("calibration-error", e.message);
  }).finally(() => {
    if (app.watching === controller) {
      $("cancel").disabled = true;
      $("start").disabled = false;
    }
  });
}

// Best objective per run over the campaign's evaluations, redrawn at most one at a time.
async function drawProgress() {
  if (app.plotting) { app.plotDue = true; return; }
  app.plotting = true;
  try {
    const runs = Math.max(0, ...app.history.map((h) => h.run_best.length));
    const x = app.history.map((h) => h.evaluations);
    const series = [];
    for (let r = 0; r < runs; r++) {
      series.push({
        label: `run ${r + 1}`, x,
        y: app.history.map((h) => {
          const v = h.run_best[r];
          return v === null || v === undefined || !(v > 0) ? null : Math.log10(v);
        }),
      });
    }
    const svg = await plot({
      title: "best objective of each run", x_label: "evaluations (all runs)",
      y_label: "log10 of the best objective", series,
    });
    $("progress-plot").replaceChildren(figure(svg, "progress: best objective of each run over the evaluations"));
  } catch (e) {
    showError("calibration-error", e.message);
  } finally {
    app.plotting = false;
    if (app.plotDue) { app.plotDue = false; drawProgress(); }
  }
}

function finish(s) {
  $("cancel").disabled = true;
  $("start").disabled = false;
  if (s.phase === 2 && s.result_json) showResult(s);
  refreshCampaigns();
}

function showResult(s) {
  const r = JSON.parse(s.result_json);
  const best = r.best;
  $("result-summary").textContent =
    `objective ${fmt(r.nominal_objective)} at the nominal point, ${fmt(best.objective)} calibrated ` +
    `(${best.method}, start ${best.start}); ${r.runs_at_best.count} of ${r.runs_at_best.of} runs reached the best; ` +
    `${r.evaluations} evaluations (${r.simulated} simulated, ${r.cached} from the store).`;
  const body = $("result-parameters").tBodies[0];
  body.replaceChildren();
  for (const p of r.free_parameters) {
    const value = best.parameters[p.name];
    const bound = best.at_bound[p.name];
    body.append(el("tr", { "data-parameter": p.name },
      el("th", { scope: "row", text: p.name }),
      el("td", { class: "num", text: fmt(p.nominal, 8) }),
      el("td", { class: "num calibrated", "data-value": String(value), text: fmt(value, 8) }),
      el("td", { class: "num", text: fmt(p.min) }),
      el("td", { class: "num", text: fmt(p.max) }),
      el("td", { class: "flag", text: bound ? `at its ${bound === "min" ? "lower" : "upper"} bound` : "inside" })));
  }
  $("download-toml").href = `/ui/campaigns/${s.id}/campaign.toml`;
  const json = $("download-json");
  if (json.href.startsWith("blob:")) URL.revokeObjectURL(json.href);
  json.href = URL.createObjectURL(new Blob([s.result_json], { type: "application/json" }));
  showResultPlots(s, r);
  $("result").hidden = false;
}

// The fit plots, per experiment (one group for a single record): the inputs the model was
// driven by first, then each output measured, nominal and calibrated; the waterfall last.
function showResultPlots(s, r) {
  const holder = $("result-plots");
  holder.replaceChildren();
  const files = s.plots || {};
  const sanitize = (n) => n.replace(/[^A-Za-z0-9._-]/g, "_");
  const experiments = (r.experiments || []).map((e) => e.name);
  const groups = experiments.length ? experiments.map((name) => ({ name, prefix: `${sanitize(name)}.` })) : [{ name: "", prefix: "" }];
  const taken = new Set(["waterfall.svg"]);
  for (const g of groups) {
    const mine = Object.keys(files).filter((f) => !taken.has(f) && f.startsWith(g.prefix) &&
      (g.prefix || !experiments.length));
    const inputs = mine.filter((f) => f.slice(g.prefix.length).startsWith("input.")).sort();
    const outputs = mine.filter((f) => !inputs.includes(f)).sort();
    if (!inputs.length && !outputs.length) continue;
    const box = el("div", { class: "plots" });
    for (const f of inputs) {
      taken.add(f);
      const input = f.slice(g.prefix.length + "input.".length).replace(/\.svg$/, "");
      box.append(figure(files[f], `${g.name ? `${g.name}: ` : ""}input ${input} as the model was driven`));
    }
    for (const f of outputs) {
      taken.add(f);
      const output = f.slice(g.prefix.length).replace(/\.svg$/, "");
      box.append(figure(files[f], `${g.name ? `${g.name}: ` : ""}${output}: measured, nominal and calibrated`));
    }
    if (g.name) {
      holder.append(el("section", { class: "experiment-plots", "aria-label": `experiment ${g.name}` },
        el("h4", { text: `Experiment ${g.name}` }), box));
    } else {
      holder.append(box);
    }
  }
  const rest = Object.keys(files).filter((f) => !taken.has(f)).sort();
  const last = el("div", { class: "plots" });
  for (const f of rest) last.append(figure(files[f], `${f.replace(/\.svg$/, "")}: measured, nominal and calibrated`));
  if (files["waterfall.svg"]) last.append(figure(files["waterfall.svg"], "waterfall: final objective of each run, best first"));
  if (last.children.length) holder.append(last);
}

async function cancel() {
  if (!app.campaignId) return;
  try {
    await call("CancelCampaign", { id: app.campaignId });
  } catch (e) {
    showError("calibration-error", e.message);
  }
}

async function refreshCampaigns() {
  try {
    const all = [];
    let token = "";
    do {
      const page = await call("ListCampaigns", { page_token: token });
      all.push(...page.campaigns);
      token = page.next_page_token;
    } while (token);
    const body = $("campaigns").tBodies[0];
    body.replaceChildren();
    const select = $("diagnosis-campaign");
    const chosen = select.value || app.campaignId;
    select.replaceChildren();
    for (const s of all) {
      const open = el("button", { type: "button", text: "Open", "aria-label": `open campaign ${s.name} ${s.id.slice(0, 8)}` });
      open.addEventListener("click", () => openCampaign(s.id));
      body.append(el("tr", {},
        el("td", { text: s.name }), el("td", { text: PHASES[s.phase] || String(s.phase) }),
        el("td", { class: "num", text: String(s.evaluations) }),
        el("td", { class: "num", text: fmt(s.best_objective) }),
        el("td", {}, el("code", { text: s.id.slice(0, 12) })), el("td", {}, open)));
      if (s.phase === 2) select.append(el("option", { value: s.id, text: `${s.name} (${s.id.slice(0, 8)}), best ${fmt(s.best_objective)}` }));
    }
    if ([...select.options].some((o) => o.value === chosen)) select.value = chosen;
  } catch (e) {
    showError("calibration-error", e.message);
  }
}

async function openCampaign(id) {
  showError("calibration-error", "");
  try {
    const s = await call("GetCampaign", { id });
    if (s.phase === 1) { watch(id); return; }
    if (app.watching) app.watching.abort();
    app.campaignId = id;
    app.campaign = s;
    $("progress-plot").replaceChildren();
    $("calibration-status").textContent = describeState(s);
    $("result").hidden = true;
    if (s.phase === 2 && s.result_json) showResult(s);
    $("result").scrollIntoView({ block: "nearest" });
  } catch (e) {
    showError("calibration-error", e.message);
  }
}

// ---- sensitivity, before a calibration --------------------------------------------------

async function analyse() {
  showError("sensitivity-error", "");
  let campaign;
  try { campaign = campaignMessage(); } catch (e) { showError("sensitivity-error", e.message); return; }
  const request = {
    campaign,
    method: $("sensitivity-method").value,
    samples: Math.round(number("sensitivity-samples")),
    seed: 1,
  };
  $("sensitivity-conclusion").hidden = true;
  $("sensitivity-table").hidden = true;
  $("sensitivity-plots").replaceChildren();
  $("analyse").disabled = true;
  $("sensitivity-status").textContent = "starting…";
  try {
    const first = await call("Sensitivity", request);
    await follow(`/api/v1/WatchAnalysis/${first.id}`, (a) => {
      $("sensitivity-status").textContent =
        `${PHASES[a.phase] || a.phase}, ${a.evaluations} of ${a.planned} evaluations` + (a.failure ? ` (${a.failure})` : "");
      if (a.phase === 2 && a.report_json) showSensitivity(a);
      if (a.phase === 3) showError("sensitivity-error", a.failure);
    });
  } catch (e) {
    showError("sensitivity-error", e.message);
  } finally {
    $("analyse").disabled = false;
  }
}

function showSensitivity(a) {
  const report = JSON.parse(a.report_json);
  $("sensitivity-conclusion").textContent = a.conclusion;
  $("sensitivity-conclusion").hidden = false;
  const body = $("sensitivity-table").tBodies[0];
  body.replaceChildren();
  for (const p of report.parameters) {
    const o = p; // the objective's statistics sit on the parameter itself
    const ci = o.total_ci ? `[${fmt(o.total_ci[0], 3)}, ${fmt(o.total_ci[1], 3)}]` : "—";
    body.append(el("tr", {},
      el("th", { scope: "row", text: p.name }),
      el("td", { class: "flag", text: p.influential ? "influential" : "can be held fixed" }),
      el("td", { class: "num", text: o.total === undefined ? "—" : fmt(o.total, 3) }),
      el("td", { class: "num", text: ci }),
      el("td", { class: "num", text: o.first === undefined ? "—" : fmt(o.first, 3) }),
      el("td", { class: "num", text: o.mu_star === undefined ? "—" : fmt(o.mu_star, 4) })));
  }
  $("sensitivity-table").hidden = false;
  const plots = $("sensitivity-plots");
  plots.replaceChildren();
  const files = a.files || {};
  const names = Object.keys(files).filter((n) => n.endsWith(".svg"))
    .sort((x, y) => (x === "sensitivity_objective.svg" ? -1 : y === "sensitivity_objective.svg" ? 1 : x.localeCompare(y)));
  // The objective's chart in view; each output's contribution one click away.
  const outputs = el("div", { class: "plots" });
  for (const name of names) {
    const what = name.replace(/^sensitivity_/, "").replace(/\.svg$/, "");
    if (what === "objective") plots.append(figure(files[name], "sensitivity of the objective"));
    else outputs.append(figure(files[name], `sensitivity of ${what}'s contribution`));
  }
  if (outputs.children.length) {
    plots.append(el("details", {}, el("summary", { text: "Sensitivity of each output's contribution" }), outputs));
  }
}

// ---- profile likelihoods, after a calibration --------------------------------------------

function clearProfiles() {
  showError("profile-error", "");
  $("profile-status").textContent = "";
  $("profile-conclusion").hidden = true;
  $("profile-table").hidden = true;
  $("profile-plots").replaceChildren();
}

async function profileParameters() {
  if (!app.campaignId) return;
  clearProfiles();
  const shown = app.campaignId;
  $("profile").disabled = true;
  $("profile-status").textContent = "profiling…";
  try {
    const first = await call("Profile", { id: shown });
    await follow(`/api/v1/WatchAnalysis/${first.id}`, (a) => {
      if (app.campaignId !== shown) return; // another campaign is shown now
      $("profile-status").textContent =
        a.phase === 1 ? "running: re-optimising along each parameter's profile…"
          : `${PHASES[a.phase] || a.phase}, ${a.evaluations} evaluations` + (a.failure ? ` (${a.failure})` : "");
      if (a.phase === 2 && a.report_json) showProfiles(a);
      if (a.phase === 3) showError("profile-error", a.failure);
    });
  } catch (e) {
    showError("profile-error", e.message);
  } finally {
    $("profile").disabled = false;
  }
}

function showProfiles(a) {
  const report = JSON.parse(a.report_json);
  $("profile-conclusion").textContent = a.conclusion;
  $("profile-conclusion").hidden = false;
  const interval = (low, high) => `[${low === null ? "open" : fmt(low, 7)}, ${high === null ? "open" : fmt(high, 7)}]`;
  const body = $("profile-table").tBodies[0];
  body.replaceChildren();
  for (const p of report.parameters) {
    body.append(el("tr", { "data-parameter": p.name },
      el("th", { scope: "row", text: p.name }),
      el("td", { class: "num", text: fmt(p.value, 8) }),
      el("td", { class: "num profile", "data-low": String(p.ci_low), "data-high": String(p.ci_high), text: interval(p.ci_low, p.ci_high) }),
      el("td", { class: "num", text: interval(p.linearised.ci_low, p.linearised.ci_high) }),
      el("td", { class: "flag", text: p.identifiable ? "identifiable" : "not identifiable" })));
  }
  $("profile-table").hidden = false;
  const plots = $("profile-plots");
  plots.replaceChildren();
  const files = a.files || {};
  for (const name of Object.keys(files).filter((n) => n.endsWith(".svg")).sort()) {
    plots.append(figure(files[name], `profile of ${name.replace(/^profile_/, "").replace(/\.svg$/, "")}: rise of the objective, threshold and linearised parabola`));
  }
}

// ---- Diagnosis tab ----------------------------------------------------------------------

async function diagnose() {
  showError("diagnosis-error", "");
  const id = $("diagnosis-campaign").value;
  if (!id) { showError("diagnosis-error", "no finished campaign: run one on the Calibration tab"); return; }
  $("verdict").hidden = true;
  $("candidates").hidden = true;
  $("diagnosis-plots").replaceChildren();
  $("diagnose").disabled = true;
  $("diagnosis-status").textContent = "diagnosing…";
  try {
    await follow(`/api/v1/Diagnose/${id}`, (d) => {
      $("diagnosis-status").textContent = `${PHASES[d.phase] || d.phase}, ${d.evaluations} evaluations` + (d.failure ? ` (${d.failure})` : "");
      if (d.phase === 2 && d.report_json) showDiagnosis(d);
      if (d.phase === 3) showError("diagnosis-error", d.failure);
    });
  } catch (e) {
    showError("diagnosis-error", e.message);
  } finally {
    $("diagnose").disabled = false;
  }
}

function showDiagnosis(d) {
  const report = JSON.parse(d.report_json);
  $("verdict").textContent = report.verdict_sentence;
  $("verdict").hidden = false;
  const body = $("candidates").tBodies[0];
  body.replaceChildren();
  for (const [i, c] of report.candidates.entries()) {
    const selected = (report.selected || []).includes(c.effect);
    body.append(el("tr", {},
      el("td", { class: "num", text: String(i + 1) }),
      el("th", { scope: "row", text: c.effect + (selected ? " (selected)" : "") }),
      el("td", { class: "num", text: fmt(c.score, 4) }),
      el("td", { class: "num", text: fmt(c.estimate, 4) }),
      el("td", { class: "num", text: Number.isFinite(c.objective) ? fmt(c.objective, 4) : "not refitted" })));
  }
  $("candidates").hidden = false;
  const plots = $("diagnosis-plots");
  plots.replaceChildren();
  const files = d.files || {};
  const order = (n) => (n.startsWith("fit_") ? 0 : n.startsWith("residual_") ? 1 : 2);
  for (const name of Object.keys(files).filter((n) => n.endsWith(".svg")).sort((a, b) => order(a) - order(b) || a.localeCompare(b))) {
    const what = name.startsWith("fit_") ? "before and after"
      : name.startsWith("residual_") ? "residual" : name.startsWith("autocorrelation") ? "autocorrelation of the residuals" : "";
    plots.append(figure(files[name], `${name.replace(/\.svg$/, "")}${what ? `: ${what}` : ""}`));
  }
}

// ---- start ------------------------------------------------------------------------------

setUpTabs();
setUpFmuDrop();
$("simulate").addEventListener("click", simulate);
$("upload").addEventListener("click", upload);
$("plot-columns").addEventListener("click", plotColumns);
$("start").addEventListener("click", start);
$("add-experiment").addEventListener("click", addExperiment);
$("cancel").addEventListener("click", cancel);
$("refresh-campaigns").addEventListener("click", refreshCampaigns);
$("diagnose").addEventListener("click", diagnose);
$("analyse").addEventListener("click", analyse);
$("profile").addEventListener("click", profileParameters);
$("login-form").addEventListener("submit", signIn);
begin();
