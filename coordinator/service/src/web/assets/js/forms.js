// Forms that say what will happen: the Calibration tab's campaign checked by the server as
// it is filled in (ValidateCampaign runs the checks SubmitCampaign runs, on the same code:
// the page re-implements none of them), each problem shown next to the field it names.
import { $, app, call, checkedValues, el, showError } from "./common.js";
import { experimentName, inputMessages } from "./experiments.js";
import { modelValue } from "./model.js";

const DEBOUNCE_MS = 400;

// The Campaign message of the form, field for field a campaign file, as the form holds it:
// an empty choice is sent empty, for the server to say what it lacks. `places` says which
// row of the page each list entry of the message came from; `local` lists the fields whose
// text is not a number at all (which no message can carry), as problems of their own.
export function campaignDraft() {
  const model = app.model, dataset = app.dataset;
  const local = [];
  const num = (id, fallback = 0) => {
    const box = $(id);
    const v = parseFloat(box.value);
    if (Number.isFinite(v)) return v;
    local.push({ id, message: "enter a number" });
    return fallback;
  };
  if (!model) return { campaign: null, places: null, local: [{ id: "calibration-context", message: "choose a model on the Model tab" }] };
  const fitted = model.outputs.filter((o) => $(`fit-${o.name}`).checked);
  const outputs = fitted.map((o) => ({
    model: o.name, measured: $(`measured-${o.name}`).value,
    weight: num(`weight-${o.name}`, 1), scale: $(`scale-${o.name}`).value,
  }));
  const free = model.parameters.filter((p) => $(`free-${p.name}`).checked);
  const parameters = free.map((p) => ({
    name: p.name, nominal: num(`nominal-${p.name}`), min: num(`min-${p.name}`),
    max: num(`max-${p.name}`), scale: $(`pscale-${p.name}`).value,
  }));
  const fixed = {};
  for (const p of model.parameters) {
    if (!free.includes(p) && modelValue(p) !== p.default_value) fixed[p.name] = modelValue(p);
  }
  const methods = checkedValues("method");
  const windowStart = num("window-start"), windowStop = num("window-stop");
  const inputs = inputMessages("");
  const places = {
    outputs: fitted.map((o) => o.name),
    parameters: free.map((p) => p.name),
    inputs: inputs.map((i) => i.model),
    experiments: [""],
  };
  const message = {
    name: $("campaign-name").value.trim(),
    model: model.name,
    fmu_id: app.fmus[model.name] ? app.fmus[model.name].id : "",
    stop_time: windowStop,
    model_parameters: fixed,
    dataset_id: dataset ? dataset.id : "",
    outputs,
    inputs,
    parameters,
    window_start: windowStart,
    window_stop: windowStop,
    defined_effects: app.definedEffects,
    search: {
      methods,
      starts: Math.round(num("starts", 1)),
      max_evaluations: Math.round(num("max-evaluations", 1000)),
      seed: Math.round(num("seed")),
      ...($("cma-population").value.trim() ? { cma_population: Math.round(num("cma-population")) } : {}),
    },
  };
  if (!app.experiments.length) return { campaign: message, places, local };
  // Several records: the first is the experiment of the fields above, each card another.
  const experiments = [{
    name: $("experiment-name").value.trim(), dataset_id: message.dataset_id,
    windows: [{ start: windowStart, stop: windowStop }], inputs,
  }];
  for (const [k, x] of app.experiments.entries()) {
    const own = {};
    for (const row of $(`${x.prefix}fixed`).tBodies[0].rows) {
      own[row.querySelector("select").value] = num(`${row.dataset.fixed}-value`);
    }
    places.experiments.push(x.prefix);
    experiments.push({
      name: experimentName(x) || `experiment ${k + 2}`, dataset_id: x.dataset ? x.dataset.id : "",
      windows: [{ start: num(`${x.prefix}window-start`), stop: num(`${x.prefix}window-stop`) }],
      fixed: own, inputs: inputMessages(x.prefix),
    });
  }
  return {
    campaign: { ...message, dataset_id: "", window_start: 0, window_stop: 0, inputs: [], experiments },
    places, local,
  };
}

// The id of the page's element that holds a field of the Campaign message (a problem's
// `field`, e.g. "outputs[1].measured"), or null when the page has none.
export function placeOf(field, places) {
  let m;
  const simple = {
    "search.methods": "methods", "search.starts": "starts", "search.max_evaluations": "max-evaluations",
    "search.seed": "seed", "search.screening": "starts", "search.cma_population": "cma-population", name: "campaign-name",
    window_start: "window-start", window_stop: "window-stop", window: "window-stop", windows: "window-stop",
    stop_time: "window-stop", outputs: "output-map", parameters: "parameter-pick", effects: "parameter-pick",
    dataset_id: "calibration-context", model: "calibration-context", fmu_id: "calibration-context",
    experiments: "experiments",
  };
  if (field in simple) return simple[field];
  if ((m = field.match(/^outputs\[(\d+)\](?:\.(\w+))?/))) {
    const name = places.outputs[+m[1]];
    if (name === undefined) return "output-map";
    return `${{ measured: "measured", weight: "weight", sigma: "weight", scale: "scale" }[m[2]] || "fit"}-${name}`;
  }
  if ((m = field.match(/^parameters\[(\d+)\](?:\.(\w+))?/))) {
    const name = places.parameters[+m[1]];
    if (name === undefined) return "parameter-pick";
    return `${{ min: "min", max: "max", nominal: "nominal", scale: "pscale" }[m[2]] || "free"}-${name}`;
  }
  if ((m = field.match(/^defined_effects\[(\d+)\]/))) {
    return $(`defined-${m[1]}`) ? `defined-${m[1]}` : "defined-effects";
  }
  if ((m = field.match(/^inputs\[(\d+)\]/))) {
    const name = places.inputs[+m[1]];
    return name === undefined ? "input-map" : `input-${name}`;
  }
  if ((m = field.match(/^experiments\[(\d+)\](?:\.(.*))?$/))) {
    const k = +m[1], rest = m[2] || "";
    const prefix = places.experiments[k];
    if (prefix === undefined) return "experiments";
    if (k === 0) {
      // The first record is the form's own fields.
      if (rest.startsWith("windows")) return rest.endsWith(".start") ? "window-start" : "window-stop";
      if (rest === "name") return "experiment-name";
      if (rest === "") return "experiment-name";
      return placeOf(rest, places);
    }
    if (rest.startsWith("windows")) return `${prefix}window-${rest.endsWith(".start") ? "start" : "stop"}`;
    if (rest === "dataset_id") return `${prefix}file`;
    if (rest === "name" || rest === "") return `${prefix}name`;
    if (rest.startsWith("fixed")) return `${prefix}fixed`;
    const input = rest.match(/^inputs\[(\d+)\]/);
    if (input) {
      const card = app.experiments[k - 1];
      const names = card ? inputMessages(card.prefix).map((i) => i.model) : [];
      return names[+input[1]] === undefined ? `${prefix}inputs` : `${prefix}input-${names[+input[1]]}`;
    }
    return `${prefix}name`;
  }
  return null;
}

// Remove every problem shown next to a field.
export function clearProblems() {
  for (const note of document.querySelectorAll(".problem")) note.remove();
  for (const field of document.querySelectorAll('[aria-invalid="true"]')) {
    field.removeAttribute("aria-invalid");
    field.removeAttribute("aria-describedby");
  }
}

// Show each problem ({field, message} from the server, or {id, message} of the page) next
// to the element it names; the ones the page has no place for are returned.
export function showProblems(problems, places) {
  clearProblems();
  const unplaced = [];
  for (const p of problems) {
    const id = p.id || (places ? placeOf(p.field, places) : null);
    const target = id && $(id);
    if (!target) { unplaced.push(p); continue; }
    const noteId = `problem-${id}`;
    let note = $(noteId);
    if (note) {
      note.textContent += `; ${p.message}`;
      continue;
    }
    note = el("p", { class: "problem", id: noteId, "data-field": p.field || id, text: p.message });
    target.setAttribute("aria-invalid", "true");
    target.setAttribute("aria-describedby", noteId);
    const cell = target.closest("td");
    const label = target.closest("label");
    if (cell) cell.append(note);
    else if (label) label.after(note);
    else if (target.tagName === "TABLE") target.before(note);
    else target.after(note);
  }
  return unplaced;
}

// The words of a problem in the error box: the field's label, then the message.
function sentence(p) {
  const id = p.id || null;
  const label = id && $(id) && ($(id).getAttribute("aria-label") || ($(id).closest("label") || {}).textContent);
  return `${(label || p.field || "campaign").trim()}: ${p.message}`;
}

let sequence = 0;   // the latest check asked; an older answer is dropped
let timer = null;

// Ask the server what is wrong with the form now and show it next to the fields: every
// problem, or none (the stale ones cleared). Answers the problems (an empty list when the
// campaign would be accepted); an error of the server itself goes to the error box.
export async function validateNow() {
  clearTimeout(timer);
  const mine = ++sequence;
  const draft = campaignDraft();
  if (!draft.campaign) {
    showProblems(draft.local, null);
    return draft.local;
  }
  let problems;
  try {
    ({ problems = [] } = await call("ValidateCampaign", { campaign: draft.campaign }));
  } catch (e) {
    if (mine === sequence) showError("calibration-error", e.message);
    return null;
  }
  if (mine !== sequence) return null;
  const all = [...draft.local, ...problems];
  // Those the form has no place for are in the list the page shows beside it.
  showProblems(all, draft.places);
  for (const p of all) p.sentence = sentence({ ...p, id: p.id || placeOf(p.field || "", draft.places) });
  return all;
}

// validateNow once the form has been left alone for a moment; only once there is something
// to check (a model and a measurement), so an empty form is not covered in messages.
export function scheduleValidation() {
  clearTimeout(timer);
  if (!app.model || !app.dataset) return;
  timer = setTimeout(validateNow, DEBOUNCE_MS);
}

// Check the form as it changes: any edit in the Calibration tab's form.
export function setUpValidation() {
  const panel = $("panel-calibration");
  for (const kind of ["input", "change"]) {
    panel.addEventListener(kind, (e) => {
      if (e.target.closest("#sensitivity, #result, #campaigns, #comparison")) return;
      scheduleValidation();
    });
  }
}

// The error box's text for problems: each in a line, with the field it concerns.
export function problemSummary(problems) {
  const lines = problems.map((p) => p.sentence || sentence(p));
  return `the campaign cannot start: ${problems.length === 1 ? "one problem" : `${problems.length} problems`}, ` +
    `shown next to ${problems.length === 1 ? "its field" : "their fields"}:\n${lines.join("\n")}`;
}
