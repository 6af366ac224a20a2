// The Model tab: the models (and uploaded FMUs), their parameters, and simulations.
import { $, INTERPOLATIONS, app, bound, call, checkedValues, el, emit, figure, fmt, modelInputs, plot, request, showError, thin } from "./common.js";

// ---- Model tab --------------------------------------------------------------------------

export async function loadModels() {
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
export async function uploadFmu(file) {
  showError("model-error", "");
  if (!file) return;
  $("fmu-status").textContent = `uploading ${file.name}…`;
  try {
    const fmu = await call(`UploadFmu?file_name=${encodeURIComponent(file.name)}`, null, {
      headers: { "Content-Type": "application/octet-stream" },
      body: await file.arrayBuffer(),
    });
    addFmuModels(fmu);
    const first = fmu.models[0];
    await chooseModel(first.name);
    $("fmu-status").textContent =
      `${fmu.file_name}: FMU ${fmu.id.slice(0, 12)}…, ${first.parameters.length} parameters, ` +
      `${first.outputs.length} outputs; models ${fmu.models.map((m) => m.name).join(", ")}`;
  } catch (e) {
    $("fmu-status").textContent = "";
    showError("model-error", e.message);
  }
}

// The models of an uploaded FMU (UploadFmu's or GetFmu's answer) in the list.
export function addFmuModels(fmu) {
  const select = $("model-select");
  for (const m of fmu.models) {
    app.fmus[m.name] = { id: fmu.id, model: m };
    if (![...select.options].some((o) => o.value === m.name)) {
      select.append(el("option", { value: m.name, text: `${m.name} (${fmu.file_name})` }));
    }
  }
}

// The model `name` chosen, as if picked in the list.
export async function chooseModel(name) {
  $("model-select").value = name;
  await describe(name);
}

export function setUpFmuDrop() {
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
export function fmuHash(name) {
  const fmu = app.fmus[name];
  if (!fmu) return undefined;
  return fmu.id.match(/../g).map((h) => parseInt(h, 16));
}

// A bound as a form value: empty when the model gives none (JSON null for ±infinity).

export async function describe(name) {
  showError("model-error", "");
  const model = app.fmus[name] ? app.fmus[name].model : (await call("Describe", { model: name })).model;
  app.model = model;
  // The stop time follows the model: how long it usually runs (its own record's length, an
  // FMU's default experiment), as the server describes it.
  if (model.default_stop_time > 0) $("model-stop").value = String(model.default_stop_time);
  $("model-description").textContent = `${model.name} (version ${model.version}): ${model.description}`;
  const body = $("model-parameters").tBodies[0];
  body.replaceChildren();
  for (const p of model.parameters) {
    const input = el("input", {
      type: "number", step: "any", value: String(p.default_value),
      id: `value-${p.name}`, "aria-label": `value of ${p.name} [${p.unit}]`,
      min: bound(p.min), max: bound(p.max),
    });
    input.addEventListener("change", () => emit("inputs-changed"));
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
  emit("inputs-changed");
}

// The model's inputs on the Model tab: each left at the model's own value, or driven by a
// column of the uploaded measurement (ids `drive-<name>`, `drive-interp-<name>`).
export function renderModelInputs() {
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
export const columnCache = {};
export async function datasetColumn(key) {
  if (!columnCache[key]) {
    const cut = key.indexOf("/");
    const id = key.slice(0, cut), column = key.slice(cut + 1);
    const response = await request(`/ui/datasets/${id}/column/${encodeURIComponent(column)}`);
    columnCache[key] = await response.json();
  }
  return columnCache[key];
}

export function modelValue(p) {
  const v = parseFloat($(`value-${p.name}`).value);
  return Number.isFinite(v) ? v : p.default_value;
}

export async function simulate() {
  showError("model-error", "");
  const model = app.model;
  const stop = parseFloat($("model-stop").value), step = parseFloat($("model-step").value);
  if (!(stop > 0 && step > 0) || stop / step > 200000) {
    showError("model-error", "stop time and step: both positive, at most 200,000 steps");
    return;
  }
  const times = [];
  for (let i = 0; i * step <= stop * (1 + 1e-12); i++) times.push(i * step);
  const outputs = checkedValues("model-output");
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
    // The previous simulation of the same model and output stays, dashed underneath: a
    // before/after of the values changed since.
    const previous = app.lastSimulation && app.lastSimulation.model === model.name ? app.lastSimulation : null;
    for (const s of answer.series) {
      const unit = (model.outputs.find((o) => o.name === s.output) || {}).unit || "";
      const [x, y] = thin(answer.times, s.values);
      const before = previous && previous.series[s.output];
      const svg = await plot({
        title: `${model.name}: ${s.output}`, x_label: "time [s]", y_label: unit ? `${s.output} [${unit}]` : s.output,
        series: [{ label: before ? "this simulation" : "simulated", x, y }],
        overlays: before ? [{ label: "previous", series: [{ label: previous.label, x: before.x, y: before.y }] }] : [],
      });
      plots.append(figure(svg, `${s.output} simulated over ${fmt(stop)} s${before ? ", the previous simulation dashed" : ""}`));
    }
    const changed = parameters.map((p) => `${p.name}=${fmt(p.value)}`).join(", ");
    app.lastSimulation = {
      model: model.name,
      label: changed || "defaults",
      series: Object.fromEntries(answer.series.map((s) => {
        const [x, y] = thin(answer.times, s.values);
        return [s.output, { x, y }];
      })),
    };
    const st = answer.statistics || {};
    $("model-status").textContent = `simulated ${fmt(stop)} s: ${st.accepted_steps} steps, ${st.events} events`;
  } catch (e) {
    $("model-status").textContent = "";
    showError("model-error", e.message);
  }
}
