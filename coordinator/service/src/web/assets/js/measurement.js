// The Measurement tab: a record uploaded, its columns plotted.
import { $, app, call, checkedValues, el, emit, fmt, request, showError } from "./common.js";
import { scheduleValidation } from "./forms.js";
import { writeRoute } from "./route.js";

// ---- Measurement tab --------------------------------------------------------------------

export async function upload() {
  const file = $("measurement-file").files[0];
  if (!file) { showError("measurement-error", "choose a file first"); return; }
  // No time column typed: the server guesses it and the page offers the file's columns.
  await uploadAs(file, $("measurement-time").value.trim());
}

// The file uploaded with its time in `time` (empty: guessed by the server). A failed upload
// changes nothing: the measurement uploaded before stays, with its columns, its plots and
// the outputs mapped onto it.
async function uploadAs(file, time) {
  showError("measurement-error", "");
  const before = $("measurement-status").textContent;
  $("measurement-status").textContent = `uploading ${file.name}…`;
  let dataset;
  try {
    const query = `file_name=${encodeURIComponent(file.name)}&time_column=${encodeURIComponent(time)}`;
    dataset = await call(`UploadDataset?${query}`, null, {
      headers: { "Content-Type": "application/octet-stream" },
      body: await file.arrayBuffer(),
    });
  } catch (e) {
    $("measurement-status").textContent = app.dataset ? before : "";
    const kept = app.dataset ? `\n${app.dataset.file_name}, uploaded before, is still the measurement in use.` : "";
    showError("measurement-error", e.message + kept);
    return;
  }
  dataset.file_name = file.name;
  app.datasetFile = file;
  showDataset(dataset);
  offerTimeColumns(dataset);
  scheduleValidation();
}

// The file's columns, its time column chosen: another choice uploads the same file again
// on that time axis (another dataset), the choice confirmed by the answer.
function offerTimeColumns(dataset) {
  const select = $("measurement-time-column");
  select.replaceChildren();
  for (const c of [dataset.time_column, ...dataset.columns]) select.append(el("option", { value: c, text: c }));
  select.value = dataset.time_column;
  $("measurement-time-choice").hidden = false;
  $("measurement-time-note").textContent = dataset.time_column_guessed
    ? `guessed from the file (a column named as time, else the first that increases); choose another if it is not the time`
    : "as named";
}

export function setUpTimeColumn() {
  $("measurement-time-column").addEventListener("change", (e) => {
    const file = app.datasetFile;
    if (file && e.target.value !== app.dataset.time_column) uploadAs(file, e.target.value);
  });
}

// `dataset` (an upload's answer, or a kept one's record) as the measurement: its columns,
// its plots, the window over all of it; the URL names it.
export function showDataset(dataset) {
  app.dataset = dataset;
  $("measurement-status").textContent =
    `${dataset.file_name}: ${dataset.samples} samples from ${fmt(dataset.start_time)} s to ${fmt(dataset.stop_time)} s; ` +
    `time in ${dataset.time_column}${dataset.time_column_guessed ? " (guessed: change it below if it is another column)" : ""}; ` +
    `columns ${dataset.columns.join(", ")}`;
  if (dataset.time_column) $("measurement-time").value = dataset.time_column;
  const box = $("measurement-columns").querySelector(".choices");
  box.replaceChildren();
  for (const c of dataset.columns) {
    box.append(el("label", {}, el("input", { type: "checkbox", name: "measured-column", value: c, checked: true }), c));
  }
  $("measurement-columns").hidden = false;
  $("window-start").value = String(dataset.start_time);
  $("window-stop").value = String(dataset.stop_time);
  emit("inputs-changed");
  plotColumns();
  writeRoute({ dataset: dataset.id });
}

// What the server keeps of the uploaded dataset `id`: its file's name, time column,
// columns, samples and time span.
export async function fetchDataset(id) {
  return (await request(`/ui/datasets/${id}`, {}, `dataset ${id}`)).json();
}

// The dataset `id` shown again (a reload, a link, a reopened campaign).
export async function restoreDataset(id) {
  showError("measurement-error", "");
  try {
    showDataset(await fetchDataset(id));
  } catch (e) {
    showError("measurement-error", e.message);
  }
}

export function plotColumns() {
  const plots = $("measurement-plots");
  plots.replaceChildren();
  for (const c of checkedValues("measured-column")) {
    const img = el("img", {
      src: `/ui/datasets/${app.dataset.id}/plot/${encodeURIComponent(c)}`,
      alt: `plot of the measured column ${c} over time`,
    });
    plots.append(el("figure", { class: "plot" }, img, el("figcaption", { text: `measured ${c}` })));
  }
}
