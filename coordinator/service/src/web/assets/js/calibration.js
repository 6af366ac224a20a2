// The Calibration tab: the form, the campaign's progress, its result and the list of campaigns.
import { $, FINISHED, PHASES, RUNNING, app, bound, call, el, emit, figure, fmt, follow, modelInputs, on, plot, showError } from "./common.js";
import { compareBox, ticked } from "./compare.js";
import { inputRows, renderExperiments } from "./experiments.js";
import { campaignDraft, clearProblems, problemSummary, validateNow } from "./forms.js";
import { modelValue } from "./model.js";
import { fillForm } from "./reopen.js";
import { writeRoute } from "./route.js";
import { showRuns } from "./runs.js";

// ---- Calibration tab --------------------------------------------------------------------

on("inputs-changed", () => renderCalibration());

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
      // A mapping whose column the measurement no longer has is no longer fitted.
      else if (was) fit.checked = false;
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

// The Campaign message of the form: field for field a campaign file ([campaignDraft]); an
// error when a field holds no number or no model is chosen.
export function campaignMessage() {
  const draft = campaignDraft();
  if (draft.local.length) {
    const [first] = draft.local;
    const box = $(first.id);
    throw new Error(`${(box && box.getAttribute("aria-label")) || first.id}: ${first.message}`);
  }
  return draft.campaign;
}

// Start the campaign of the form, once the server finds nothing wrong with it: otherwise
// each problem is shown next to its field and listed in the error box, and nothing starts.
export async function start() {
  showError("calibration-error", "");
  clearProblems();
  const problems = await validateNow();
  if (problems === null) return; // the check itself failed: its error is shown
  if (problems.length) {
    showError("calibration-error", problemSummary(problems));
    return;
  }
  try {
    const { id, started } = await call("SubmitCampaign", { campaign: campaignDraft().campaign });
    $("calibration-status").textContent = started ? "started" : "known already: showing it";
    watch(id);
  } catch (e) {
    showError("calibration-error", e.message);
  }
}

// The campaign's state in a line: phase, evaluations, best objective, runs at the best (as
// the server counts them, by the rule of result.json's runs_at_best).
export function describeState(s) {
  const atBest = s.runs_at_best || {};
  let text = `${s.name}: ${PHASES[s.phase] || s.phase}, ${s.evaluations} evaluations, best objective ${fmt(s.best_objective)}`;
  if (atBest.of) text += `, ${atBest.count || 0} of ${atBest.of} runs at the best`;
  // Why it failed goes to the error box (showFailure), not here.
  return text;
}

// Show campaign state `s`: its status, progress history, runs and, once it has ended, its
// result or what it had found.
function showState(s) {
  app.campaign = s;
  $("calibration-status").textContent = describeState(s);
  showFailure(s);
  if ((s.history || []).length) drawProgress();
  showRuns(s, parameterNames(s));
  $("campaign-actions").hidden = s.phase === RUNNING || !s.campaign;
  $("use-values").hidden = !Object.keys(s.best_parameters || {}).length;
  showBestSoFar(s);
}

// The free parameters' names in the campaign's order.
function parameterNames(s) {
  if (s.result) return s.result.free_parameters.map((p) => p.name);
  const c = s.campaign || {};
  const defined = (c.defined_effects || []).flatMap((e) =>
    (e.parameters || []).filter((p) => !p.fixed && !e.fixed).map((p) => ({ name: `${e.name}.${p.name}` })));
  return [...(c.parameters || []), ...(c.effects || []), ...defined].map((p) => p.name);
}

// A failed campaign's reason, in the error box.
export function showFailure(s) {
  if (s.failure) showError("calibration-error", s.failure);
}

export function watch(id) {
  if (app.watching) app.watching.abort();
  app.campaignId = id;
  writeRoute({ campaign: id });
  $("result").hidden = true;
  $("best-so-far").hidden = true;
  emit("campaign-shown", id);
  $("progress-plot").replaceChildren();
  $("cancel").disabled = false;
  $("start").disabled = true;
  const controller = new AbortController();
  app.watching = controller;
  follow(`/api/v1/WatchCampaign/${id}`, (s) => {
    showState(s);
    if (s.phase !== RUNNING) finish(s);
  }, controller.signal).catch((e) => {
    if (e.name !== "AbortError") showError("calibration-error", e.message);
  }).finally(() => {
    if (app.watching === controller) {
      $("cancel").disabled = true;
      $("start").disabled = false;
    }
  });
}

// Best objective per run over the campaign's evaluations (the history the server keeps),
// each run named by its label; redrawn at most one at a time.
export async function drawProgress() {
  if (app.plotting) { app.plotDue = true; return; }
  app.plotting = true;
  try {
    const s = app.campaign;
    const history = s.history || [];
    const runs = Math.max(0, ...history.map((h) => (h.run_best || []).length));
    const x = history.map((h) => h.evaluations);
    const series = [];
    for (let r = 0; r < runs; r++) {
      const run = (s.runs || [])[r];
      series.push({
        label: run ? run.label : `run ${r + 1}`, x,
        y: history.map((h) => {
          const v = (h.run_best || [])[r];
          return v === null || v === undefined || !(v > 0) ? null : v;
        }),
      });
    }
    const svg = await plot({
      title: "best objective of each run", x_label: "evaluations (all runs)",
      y_label: "best objective", y_scale: "log", direct_labels: runs <= 12, series,
    });
    if (app.campaign && app.campaign.id === s.id) {
      $("progress-plot").replaceChildren(figure(svg, "progress: best objective of each run over the evaluations"));
    }
  } catch (e) {
    showError("calibration-error", e.message);
  } finally {
    app.plotting = false;
    if (app.plotDue) { app.plotDue = false; drawProgress(); }
  }
}

// What a campaign that stopped before its end had found: each free parameter's best value
// so far.
function showBestSoFar(s) {
  const best = s.best_parameters || {};
  const names = parameterNames(s).filter((n) => n in best);
  const show = s.phase !== RUNNING && s.phase !== FINISHED && names.length > 0;
  $("best-so-far").hidden = !show;
  if (!show) return;
  $("best-so-far-note").textContent =
    `${s.name} was ${PHASES[s.phase] || s.phase} after ${s.evaluations} evaluations; ` +
    `the best point any run had found, objective ${fmt(s.best_objective)}:`;
  const body = $("best-so-far-parameters").tBodies[0];
  body.replaceChildren();
  for (const n of names) {
    body.append(el("tr", { "data-parameter": n },
      el("th", { scope: "row", text: n }),
      el("td", { class: "num", "data-value": String(best[n]), text: fmt(best[n], 8) })));
  }
}

// "Edit and re-run": the form holds the shown campaign's spec; it is brought into view to
// be changed and started as a new campaign (the shown one stays as it was).
export async function editAndRerun() {
  const s = app.campaign;
  if (!s || !s.campaign) return;
  showError("calibration-error", "");
  try {
    await fillForm(s.campaign);
    $("calibration-status").textContent =
      `The form holds the spec of ${s.name} (${s.id.slice(0, 8)}): change it and start a new campaign.`;
    const table = $("parameter-pick");
    table.scrollIntoView({ block: "start" });
    const first = table.querySelector('input[id^="min-"]');
    if (first) first.focus();
  } catch (e) {
    showError("calibration-error", e.message);
  }
}

// "Use these values": the calibrated (or best so far) values as the Model tab's values.
export function useValues() {
  const best = (app.campaign && app.campaign.best_parameters) || {};
  for (const [name, value] of Object.entries(best)) {
    const field = $(`value-${name}`);
    if (!field) continue;
    field.value = String(value);
    field.dispatchEvent(new Event("change"));
  }
  $("tab-model").click();
}

export function finish(s) {
  $("cancel").disabled = true;
  $("start").disabled = false;
  if (s.phase === FINISHED && s.result) showResult(s);
  refreshCampaigns();
}

export function showResult(s) {
  const r = s.result;
  const best = r.best;
  $("result-summary").textContent =
    `objective ${fmt(r.nominal_objective)} at the nominal point, ${fmt(best.objective)} calibrated ` +
    `(${best.method}, start ${best.start}); ${r.runs_at_best.count} of ${r.runs_at_best.of} runs reached the best; ` +
    `${r.evaluations} evaluations (${r.simulated} simulated, ${r.from_store} from the store).`;
  const body = $("result-parameters").tBodies[0];
  body.replaceChildren();
  for (const p of r.free_parameters) {
    const value = best.parameters[p.name];
    const bound = (best.at_bound || {})[p.name];
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
export function showResultPlots(s, r) {
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

export async function cancel() {
  if (!app.campaignId) return;
  try {
    await call("CancelCampaign", { id: app.campaignId });
  } catch (e) {
    showError("calibration-error", e.message);
  }
}

export async function refreshCampaigns() {
  try {
    const all = [];
    let token = "";
    do {
      const page = await call("ListCampaigns", { page_token: token });
      all.push(...page.campaigns);
      token = page.next_page_token;
    } while (token);
    const body = $("campaigns").tBodies[0];
    const wasTicked = new Set(ticked());
    body.replaceChildren();
    const select = $("diagnosis-campaign");
    const chosen = select.value || app.campaignId;
    select.replaceChildren();
    for (const s of all) {
      const open = el("button", { type: "button", text: "Open", "aria-label": `open campaign ${s.name} ${s.id.slice(0, 8)}` });
      open.addEventListener("click", () => openCampaign(s.id));
      body.append(el("tr", {}, compareBox(s, wasTicked.has(s.id)),
        el("td", { text: s.name }), el("td", { text: PHASES[s.phase] || String(s.phase) }),
        el("td", { class: "num", text: String(s.evaluations) }),
        el("td", { class: "num", text: fmt(s.best_objective) }),
        el("td", {}, el("code", { text: s.id.slice(0, 12) })), el("td", {}, open)));
      if (s.phase === FINISHED) select.append(el("option", { value: s.id, text: `${s.name} (${s.id.slice(0, 8)}), best ${fmt(s.best_objective)}` }));
    }
    if ([...select.options].some((o) => o.value === chosen)) select.value = chosen;
  } catch (e) {
    showError("calibration-error", e.message);
  }
}

// Open campaign `id`: the form filled with its spec (and its dataset), its progress
// history, runs and result as the server keeps them; followed on if it is running.
export async function openCampaign(id) {
  showError("calibration-error", "");
  try {
    const s = await call("GetCampaign", { id });
    if (s.campaign) await fillForm(s.campaign);
    if (s.phase === RUNNING) { watch(id); return; }
    if (app.watching) app.watching.abort();
    app.campaignId = id;
    writeRoute({ campaign: id });
    $("progress-plot").replaceChildren();
    $("result").hidden = true;
    emit("campaign-shown", id);
    showState(s);
    if (s.phase === FINISHED && s.result) showResult(s);
    $("result").scrollIntoView({ block: "nearest" });
  } catch (e) {
    showError("calibration-error", e.message);
  }
}
