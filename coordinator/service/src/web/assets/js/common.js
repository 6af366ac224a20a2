// What every tab uses: the app's state, the events the tabs tell each other, DOM helpers,
// number formatting, the one fetch every route goes through, the APIs over HTTP JSON
// (/api/v1/<Method>) and plots drawn by the server (/ui/plot).

// A campaign's or an analysis' phase, as the API names it, and in words.
export const RUNNING = "CAMPAIGN_PHASE_RUNNING";
export const FINISHED = "CAMPAIGN_PHASE_FINISHED";
export const FAILED = "CAMPAIGN_PHASE_FAILED";
export const PHASES = {
  CAMPAIGN_PHASE_UNSPECIFIED: "unknown", [RUNNING]: "running", [FINISHED]: "finished",
  [FAILED]: "failed", CAMPAIGN_PHASE_CANCELLED: "cancelled",
};

/**
 * The page's state. Messages of the API are as its JSON gives them (`any`).
 * @typedef {object} App
 * @property {any} model
 * @property {Object<string, {id: string, model: any}>} fmus
 * @property {any} dataset
 * @property {string | null} campaignId
 * @property {any} campaign
 * @property {AbortController | null} watching
 * @property {boolean} plotting
 * @property {boolean} plotDue
 * @property {boolean} started
 * @property {{key: number, prefix: string, dataset: any, card: HTMLElement, fixed: any}[]} experiments
 * @property {any[]} definedEffects
 * @property {number} nextExperiment
 * @property {File | null} datasetFile
 * @property {{model: string, [k: string]: any} | null} lastSimulation
 */
/** @type {App} */
export const app = {
  model: null,        // ModelDescription of the chosen model
  fmus: {},           // uploaded FMUs' models by name: {id, model: ModelDescription}
  dataset: null,      // Dataset answered by UploadDataset (with file_name)
  campaignId: null,   // the campaign shown on the Calibration tab
  campaign: null,     // its CampaignState (its progress history and runs the server's)
  watching: null,     // AbortController of the watch
  plotting: false,
  plotDue: false,
  started: false,     // the tabs' contents are loaded (after the login, if one is asked)
  experiments: [],    // further records: {key, prefix, dataset, card, fixed}
  definedEffects: [], // effects defined by a formula in the form (DefinedEffect messages)
  nextExperiment: 0,  // key of the next experiment added
  datasetFile: null,  // the measurement file chosen, until it is uploaded
  lastSimulation: null, // the model's last simulation shown, to redraw it beside the next
};

// ---- events ------------------------------------------------------------------------------
// What one tab tells the others, so that no module imports the one that imports it:
// "inputs-changed" (the model, its values or the measurement changed: the Calibration tab
// redraws its form) and "campaign-shown" (another campaign is shown: its analyses go).
const events = new EventTarget();
export const on = (name, handler) =>
  events.addEventListener(name, (e) => handler(/** @type {CustomEvent} */ (e).detail));
export const emit = (name, detail) => events.dispatchEvent(new CustomEvent(name, { detail }));

// An element of the page by id. Typed `any`: the page holds inputs, selects, tables and
// links by id, and each caller knows which it asked for.
/** @type {(id: string) => any} */
export const $ = (id) => document.getElementById(id);

/**
 * The check boxes (or radio buttons) of the form named `name`, or only those checked.
 * @param {string} name
 * @param {boolean} [checkedOnly]
 * @returns {HTMLInputElement[]}
 */
export function boxes(name, checkedOnly = false) {
  const selector = `input[name="${name}"]${checkedOnly ? ":checked" : ""}`;
  return [.../** @type {NodeListOf<HTMLInputElement>} */ (document.querySelectorAll(selector))];
}

/** The values of the boxes named `name` that are checked. @param {string} name */
export const checkedValues = (name) => boxes(name, true).map((box) => box.value);

export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k === "text") node.textContent = v;
    else if (v !== undefined && v !== null && v !== false) node.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children) node.append(c);
  return node;
}

export function fmt(v, digits = 6) {
  if (v === null || v === undefined || !Number.isFinite(v)) return "—";
  if (v === 0) return "0";
  const a = Math.abs(v);
  const rounded = Number(v.toPrecision(digits));
  return a >= 1e-3 && a < 1e6 ? String(rounded) : rounded.toExponential();
}

export function showError(id, message) {
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

// The one fetch of every route: its answer when it is ok; otherwise the login asked for
// (401) and an Error with the server's message (`what` names the call when it gave none).
export async function request(url, init = {}, what = url) {
  const response = await fetch(url, init);
  if (response.ok) return response;
  if (response.status === 401) showLogin();
  const text = await response.text();
  let message = text;
  try { message = JSON.parse(text).message; } catch { /* plain text */ }
  throw new Error(message || `${what}: HTTP ${response.status}`);
}

// The init of a POST of `body` as JSON.
export const post = (body) => ({
  method: "POST",
  headers: { "Content-Type": "application/json" },
  body: JSON.stringify(body),
});

export async function call(method, message, init = {}) {
  const response = await request(`/api/v1/${method}`, {
    method: "POST",
    headers: init.headers || { "Content-Type": "application/json" },
    body: init.body !== undefined ? init.body : JSON.stringify(message || {}),
  }, method);
  return response.json();
}

// A server stream (Server-Sent Events, one whole state each) until it ends.
export async function follow(url, onState, signal) {
  const response = await request(url, { signal });
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
export function figure(svgText, caption) {
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

export async function plot(what) {
  return (await request("/ui/plot", post(what), "plot")).text();
}

// ---- the login --------------------------------------------------------------------------
// A server with a token (calib coordinator --token-file) asks for it once: POST /login
// with it as the bearer token answers with a session cookie (HttpOnly, SameSite=Strict)
// that every later call carries. The page never keeps the token.

export function showLogin() {
  document.body.classList.add("signing-in");
  $("login").hidden = false;
  $("login-token").focus();
}

// A bound as a form value: empty when the model gives none (JSON null for ±infinity).
export const bound = (v) => (Number.isFinite(v) ? String(v) : "");

// At most `n` points of a series, for drawing.
export function thin(x, y, n = 20000) {
  const step = Math.max(1, Math.ceil(x.length / n));
  if (step === 1) return [x, y];
  return [x.filter((_, k) => k % step === 0), y.filter((_, k) => k % step === 0)];
}

export function number(id) {
  const v = parseFloat($(id).value);
  if (!Number.isFinite(v)) throw new Error(`${$(id).getAttribute("aria-label") || id}: not a number`);
  return v;
}

// ---- model inputs -----------------------------------------------------------------------

export const INTERPOLATIONS = [["linear", "linear"], ["hold", "held (zero-order hold)"]];

export const modelInputs = () => (app.model && app.model.inputs) || [];
