// ---- Diagnosis tab ----------------------------------------------------------------------
import { $, FAILED, FINISHED, PHASES, el, figure, fmt, follow, showError } from "./common.js";
import { clearDiscovery, showDiscovery } from "./discovery.js";

export async function diagnose() {
  showError("diagnosis-error", "");
  const id = $("diagnosis-campaign").value;
  if (!id) { showError("diagnosis-error", "no finished campaign: run one on the Calibration tab"); return; }
  $("verdict").hidden = true;
  $("candidates").hidden = true;
  $("diagnosis-plots").replaceChildren();
  clearDiscovery();
  $("diagnose").disabled = true;
  const discover = $("diagnosis-discover").checked;
  $("diagnosis-status").textContent = discover ? "diagnosing, then looking outside the library…" : "diagnosing…";
  try {
    await follow(`/api/v1/Diagnose/${id}${discover ? "?discover=true" : ""}`, (d) => {
      $("diagnosis-status").textContent = `${PHASES[d.phase] || d.phase}, ${d.evaluations} evaluations` + (d.failure ? ` (${d.failure})` : "");
      if (d.phase === FINISHED && d.report) showDiagnosis(d);
      if (d.phase === FINISHED && d.found_outside_the_library) showDiscovery(d.found_outside_the_library, d.campaign_id);
      if (d.phase === FAILED) showError("diagnosis-error", d.failure);
    });
  } catch (e) {
    showError("diagnosis-error", e.message);
  } finally {
    $("diagnose").disabled = false;
  }
}

export function showDiagnosis(d) {
  const report = d.report;
  $("verdict").textContent = report.verdict_sentence;
  $("verdict").hidden = false;
  const body = $("candidates").tBodies[0];
  body.replaceChildren();
  for (const [i, c] of report.candidates.entries()) {
    const selected = (report.selected || []).includes(c.effect);
    body.append(el("tr", {},
      el("td", { class: "num", text: String(i + 1) }),
      el("th", { scope: "row", text: c.effect + (selected ? " (selected)" : "") }),
      el("td", { class: "num", text: fmt(c.score, 4) }),
      el("td", { class: "num", text: fmt(c.estimate, 4) }),
      el("td", { class: "num", text: Number.isFinite(c.objective) ? fmt(c.objective, 4) : "not refitted" })));
  }
  $("candidates").hidden = false;
  const plots = $("diagnosis-plots");
  plots.replaceChildren();
  const files = d.files || {};
  const order = (n) => (n.startsWith("fit_") ? 0 : n.startsWith("residual_") ? 1 : 2);
  for (const name of Object.keys(files).filter((n) => n.endsWith(".svg")).sort((a, b) => order(a) - order(b) || a.localeCompare(b))) {
    const what = name.startsWith("fit_") ? "before and after"
      : name.startsWith("residual_") ? "residual" : name.startsWith("autocorrelation") ? "autocorrelation of the residuals" : "";
    plots.append(figure(files[name], `${name.replace(/\.svg$/, "")}${what ? `: ${what}` : ""}`));
  }
}
