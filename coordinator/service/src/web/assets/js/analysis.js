// Sensitivity before a calibration, profile likelihoods after it (the Calibration tab).
import { campaignMessage } from "./calibration.js";
import { $, FAILED, FINISHED, PHASES, RUNNING, app, call, el, figure, fmt, follow, number, on, showError } from "./common.js";

// ---- sensitivity, before a calibration --------------------------------------------------

export async function analyse() {
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
      if (a.phase === FINISHED && a.sensitivity) showSensitivity(a);
      if (a.phase === FAILED) showError("sensitivity-error", a.failure);
    });
  } catch (e) {
    showError("sensitivity-error", e.message);
  } finally {
    $("analyse").disabled = false;
  }
}

export function showSensitivity(a) {
  const report = a.sensitivity;
  $("sensitivity-conclusion").textContent = a.conclusion;
  $("sensitivity-conclusion").hidden = false;
  const body = $("sensitivity-table").tBodies[0];
  body.replaceChildren();
  for (const p of report.parameters) {
    const o = p; // the objective's statistics sit on the parameter itself
    const ci = o.total_ci.length ? `[${fmt(o.total_ci[0], 3)}, ${fmt(o.total_ci[1], 3)}]` : "—";
    body.append(el("tr", {},
      el("th", { scope: "row", text: p.name }),
      el("td", { class: "flag", text: p.influential ? "influential" : "can be held fixed" }),
      el("td", { class: "num", text: o.total === null ? "—" : fmt(o.total, 3) }),
      el("td", { class: "num", text: ci }),
      el("td", { class: "num", text: o.first === null ? "—" : fmt(o.first, 3) }),
      el("td", { class: "num", text: o.mu_star === null ? "—" : fmt(o.mu_star, 4) })));
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

on("campaign-shown", () => clearProfiles());

export function clearProfiles() {
  showError("profile-error", "");
  $("profile-status").textContent = "";
  $("profile-conclusion").hidden = true;
  $("profile-table").hidden = true;
  $("profile-plots").replaceChildren();
}

export async function profileParameters() {
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
        a.phase === RUNNING ? "running: re-optimising along each parameter's profile…"
          : `${PHASES[a.phase] || a.phase}, ${a.evaluations} evaluations` + (a.failure ? ` (${a.failure})` : "");
      if (a.phase === FINISHED && a.profile) showProfiles(a);
      if (a.phase === FAILED) showError("profile-error", a.failure);
    });
  } catch (e) {
    showError("profile-error", e.message);
  } finally {
    $("profile").disabled = false;
  }
}

export function showProfiles(a) {
  const report = a.profile;
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
