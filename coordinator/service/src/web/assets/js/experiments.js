// Inputs driven by measured columns, and further experiments (records) of a campaign.
import { $, INTERPOLATIONS, app, call, el, fmt, modelInputs, showError } from "./common.js";
import { modelValue, renderModelInputs } from "./model.js";

// ---- inputs and experiments -------------------------------------------------------------

// A row per model input in `body`: the measured column driving it (ids `<prefix>input-<name>`)
// and how it is read between samples (`<prefix>interp-<name>`), keeping what the rows held.
export function inputRows(body, prefix, columns, whose) {
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
export function inputMessages(prefix) {
  return modelInputs()
    .filter((i) => $(`${prefix}input-${i.name}`) && $(`${prefix}input-${i.name}`).value)
    .map((i) => ({
      model: i.name, measured: $(`${prefix}input-${i.name}`).value,
      interpolation: $(`${prefix}interp-${i.name}`).value,
    }));
}

export function addExperiment() {
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
      field("Time column", { type: "text", id: `${x}time`, value: app.dataset ? app.dataset.time_column : "", placeholder: "guessed from the file" }),
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
export function addFixedValue(experiment) {
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

export function experimentName(experiment) {
  const box = $(`${experiment.prefix}name`);
  return box ? box.value.trim() : "";
}

// The experiments' cards follow the model (its inputs and parameters) and the first record.
export function renderExperiments() {
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

export async function uploadExperiment(experiment) {
  const x = experiment.prefix;
  showError(`${x}error`, "");
  const file = $(`${x}file`).files[0];
  if (!file) { showError(`${x}error`, "choose a file first"); return; }
  const time = $(`${x}time`).value.trim();
  const before = $(`${x}status`).textContent;
  $(`${x}status`).textContent = `uploading ${file.name}…`;
  try {
    const query = `file_name=${encodeURIComponent(file.name)}&time_column=${encodeURIComponent(time)}`;
    const dataset = await call(`UploadDataset?${query}`, null, {
      headers: { "Content-Type": "application/octet-stream" },
      body: await file.arrayBuffer(),
    });
    dataset.file_name = file.name;
    experiment.dataset = dataset;
    $(`${x}time`).value = dataset.time_column;
    $(`${x}status`).textContent =
      `${file.name}: ${dataset.samples} samples from ${fmt(dataset.start_time)} s to ${fmt(dataset.stop_time)} s; ` +
      `time in ${dataset.time_column}${dataset.time_column_guessed ? " (guessed: type another and upload again if it is not the time)" : ""}; ` +
      `columns ${dataset.columns.join(", ")}`;
    $(`${x}window-start`).value = String(dataset.start_time);
    $(`${x}window-stop`).value = String(dataset.stop_time);
    renderExperiments();
  } catch (e) {
    // The record uploaded before, if any, stays this experiment's.
    $(`${x}status`).textContent = experiment.dataset ? before : "";
    showError(`${x}error`, e.message);
  }
}
