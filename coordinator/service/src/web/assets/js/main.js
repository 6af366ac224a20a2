// calib web app. Every call goes to the Calibration and Simulator APIs over HTTP JSON
// (/api/v1/<Method>, the RPC's request and answer messages); plots are SVG drawn by the
// server's plotting code (/ui/...). No framework, no build step: ES modules, one per tab
// (model.js, measurement.js, calibration.js with experiments.js and analysis.js,
// diagnosis.js) over common.js; this one wires them to the page.
import { analyse, profileParameters } from "./analysis.js";
import { cancel, editAndRerun, openCampaign, refreshCampaigns, start, useValues } from "./calibration.js";
import { $, app, showError, showLogin } from "./common.js";
import { compareTicked } from "./compare.js";
import { diagnose } from "./diagnosis.js";
import { addExperiment } from "./experiments.js";
import { setUpValidation } from "./forms.js";
import { plotColumns, restoreDataset, setUpTimeColumn, upload } from "./measurement.js";
import { loadModels, setUpFmuDrop, simulate } from "./model.js";
import { readRoute, writeRoute } from "./route.js";

// ---- the login --------------------------------------------------------------------------
// A server with a token (calib coordinator --token-file) asks for it once: POST /login
// with it as the bearer token answers with a session cookie (HttpOnly, SameSite=Strict)
// that every later call carries. The page never keeps the token.

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
  refreshCampaigns();
  await loadModels();
  await restore();
}

// What the URL names, again: its tab, its campaign (the form filled with its spec, its
// dataset, its progress and result) or its dataset.
async function restore() {
  const route = readRoute();
  selectTab($(`tab-${route.tab}`));
  if (route.campaign) await openCampaign(route.campaign);
  else if (route.dataset) await restoreDataset(route.dataset);
  writeRoute({ tab: route.tab });
}

// ---- tabs -------------------------------------------------------------------------------

function selectTab(tab, focus = false) {
  for (const t of /** @type {NodeListOf<HTMLElement>} */ (document.querySelectorAll('[role="tab"]'))) {
    const on = t === tab;
    t.setAttribute("aria-selected", String(on));
    t.tabIndex = on ? 0 : -1;
    $(t.getAttribute("aria-controls")).hidden = !on;
  }
  if (focus) tab.focus();
  writeRoute({ tab: tab.id.replace(/^tab-/, "") });
  if (tab.id === "tab-diagnosis") refreshCampaigns();
}

function setUpTabs() {
  const tabs = [...document.querySelectorAll('[role="tab"]')];
  for (const [i, tab] of tabs.entries()) {
    tab.addEventListener("click", () => selectTab(tab));
    tab.addEventListener("keydown", (/** @type {KeyboardEvent} */ e) => {
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
$("compare").addEventListener("click", compareTicked);
setUpValidation();
setUpTimeColumn();
$("diagnose").addEventListener("click", diagnose);
$("analyse").addEventListener("click", analyse);
$("profile").addEventListener("click", profileParameters);
$("login-form").addEventListener("submit", signIn);
$("edit-rerun").addEventListener("click", editAndRerun);
$("use-values").addEventListener("click", useValues);
// A link to another campaign or dataset followed within the page.
window.addEventListener("hashchange", () => { if (app.started) restore(); });
begin();
