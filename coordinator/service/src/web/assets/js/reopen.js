// A campaign's spec (the Campaign message it was submitted with, which the server keeps)
// back in the form: its model and fixed values, its dataset, outputs, inputs, free
// parameters, window, search and further experiments. What the user then changes and
// starts is a new campaign; the old one stays as it was.
import { $, app, boxes, call, emit, fmt, modelInputs } from "./common.js";
import { setDefinedEffects } from "./effects.js";
import { addExperiment, addFixedValue, renderExperiments } from "./experiments.js";
import { fetchDataset, showDataset } from "./measurement.js";
import { addFmuModels, chooseModel } from "./model.js";

const set = (id, value) => {
  const field = $(id);
  if (field && value !== undefined && value !== null) field.value = String(value);
};

// Fill the form with `message` (a Campaign message as JSON).
export async function fillForm(message) {
  // The model: a hosted one, or an uploaded FMU's.
  if (message.fmu_id) {
    addFmuModels(await call("GetFmu", { id: message.fmu_id }));
  }
  await chooseModel(message.model);
  const model = app.model;
  // Its fixed values are the Model tab's values.
  for (const p of model.parameters) {
    const fixed = (message.model_parameters || {})[p.name];
    set(`value-${p.name}`, fixed === undefined ? p.default_value : fixed);
  }
  if (message.stop_time) set("model-stop", message.stop_time);
  // The records: the campaign's dataset, or its experiments' (the first on the
  // Measurement tab, each other on a card of its own).
  const experiments = message.experiments || [];
  for (const x of [...app.experiments]) x.card.remove();
  app.experiments = [];
  const first = experiments.length ? experiments[0] : null;
  const datasetId = first ? first.dataset_id : message.dataset_id;
  if (datasetId) showDataset(await fetchDataset(datasetId));
  emit("inputs-changed");
  // Outputs compared, and how.
  for (const o of model.outputs) {
    const m = (message.outputs || []).find((x) => x.model === o.name);
    $(`fit-${o.name}`).checked = Boolean(m);
    if (m) {
      set(`measured-${o.name}`, m.measured);
      set(`weight-${o.name}`, m.weight === undefined || m.weight === null ? 1 : m.weight);
      set(`scale-${o.name}`, m.scale || "none");
    }
  }
  // Free parameters, their start and bounds.
  for (const p of model.parameters) {
    const m = (message.parameters || []).find((x) => x.name === p.name);
    $(`free-${p.name}`).checked = Boolean(m);
    if (m) {
      set(`nominal-${p.name}`, m.nominal);
      set(`min-${p.name}`, m.min);
      set(`max-${p.name}`, m.max);
      set(`pscale-${p.name}`, m.scale || "lin");
    }
  }
  // Effects defined by a formula.
  setDefinedEffects(message.defined_effects);
  // The window and the inputs of the first record.
  const window = first && first.windows && first.windows.length ? first.windows[0]
    : { start: message.window_start, stop: message.window_stop };
  set("window-start", window.start);
  set("window-stop", window.stop);
  setInputs("", first ? first.inputs : message.inputs);
  // The search.
  set("campaign-name", message.name);
  const search = message.search || {};
  const methods = search.methods && search.methods.length ? search.methods : ["nelder-mead"];
  for (const box of boxes("method")) box.checked = methods.includes(box.value);
  set("starts", search.starts || 1);
  set("max-evaluations", search.max_evaluations || 1000);
  set("seed", search.seed || 0);
  set("cma-population", search.cma_population || "");
  // Further experiments, each on its card.
  if (first) set("experiment-name", first.name);
  for (const e of experiments.slice(1)) {
    addExperiment();
    const x = app.experiments[app.experiments.length - 1];
    set(`${x.prefix}name`, e.name);
    if (e.dataset_id) {
      const dataset = await fetchDataset(e.dataset_id);
      x.dataset = dataset;
      set(`${x.prefix}time`, dataset.time_column);
      $(`${x.prefix}status`).textContent =
        `${dataset.file_name}: ${dataset.samples} samples from ${fmt(dataset.start_time)} s to ${fmt(dataset.stop_time)} s; ` +
        `columns ${dataset.columns.join(", ")}`;
    }
    const w = (e.windows || [])[0];
    if (w) {
      set(`${x.prefix}window-start`, w.start);
      set(`${x.prefix}window-stop`, w.stop);
    }
    for (const [name, value] of Object.entries(e.fixed || {})) {
      addFixedValue(x);
      const row = $(`${x.prefix}fixed`).tBodies[0].lastElementChild;
      set(`${row.dataset.fixed}-name`, name);
      set(`${row.dataset.fixed}-value`, value);
    }
    renderExperiments();
    setInputs(x.prefix, e.inputs);
  }
  renderExperiments();
}

// The rows `<prefix>input-<name>` set to `inputs` (Input messages).
function setInputs(prefix, inputs) {
  for (const i of modelInputs()) {
    const m = (inputs || []).find((x) => x.model === i.name);
    set(`${prefix}input-${i.name}`, m ? m.measured : "");
    if (m) set(`${prefix}interp-${i.name}`, m.interpolation || "linear");
  }
}
