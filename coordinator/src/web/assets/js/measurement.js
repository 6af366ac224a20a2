// The Measurement tab: a record uploaded, its columns plotted.
import { renderCalibration } from "./calibration.js";
import { $, app, call, el, fmt, showError, showLogin } from "./common.js";
import { writeRoute } from "./route.js";

// ---- Measurement tab --------------------------------------------------------------------

export async function upload() {
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
    dataset.time_column = time;
    showDataset(dataset);
  } catch (e) {
    app.dataset = null;
    $("measurement-status").textContent = "";
    $("measurement-columns").hidden = true;
    $("measurement-plots").replaceChildren();
    showError("measurement-error", e.message);
    renderCalibration();
  }
}

// `dataset` (an upload's answer, or a kept one's record) as the measurement: its columns,
// its plots, the window over all of it; the URL names it.
export function showDataset(dataset) {
  app.dataset = dataset;
  $("measurement-status").textContent =
    `${dataset.file_name}: ${dataset.samples} samples from ${fmt(dataset.start_time)} s to ${fmt(dataset.stop_time)} s; ` +
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
  renderCalibration();
  plotColumns();
  writeRoute({ dataset: dataset.id });
}

// What the server keeps of the uploaded dataset `id`: its file's name, time column,
// columns, samples and time span.
export async function fetchDataset(id) {
  const response = await fetch(`/ui/datasets/${id}`);
  const text = await response.text();
  if (response.status === 401) showLogin();
  let answer;
  try { answer = JSON.parse(text); } catch { answer = { message: text }; }
  if (!response.ok) throw new Error(answer.message || `dataset ${id}: HTTP ${response.status}`);
  return answer;
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
  for (const input of document.querySelectorAll('input[name="measured-column"]:checked')) {
    const c = input.value;
    const img = el("img", {
      src: `/ui/datasets/${app.dataset.id}/plot/${encodeURIComponent(c)}`,
      alt: `plot of the measured column ${c} over time`,
    });
    plots.append(el("figure", { class: "plot" }, img, el("figcaption", { text: `measured ${c}` })));
  }
}
