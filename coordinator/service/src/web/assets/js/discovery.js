// The Diagnosis tab's "found outside the library": discovery's proposals as the server
// computed them (DiagnosisState.found_outside_the_library: the formula in symbols and in
// words, each term's estimate with its 95% interval and proposed bounds, the objective
// before and after the refit), and the button that adds a proposal to the campaign's form
// so that its next run fits it. The page computes none of these figures.
import { $, call, el, fmt, showError } from "./common.js";
import { addDefinedEffect } from "./effects.js";
import { fillForm } from "./reopen.js";

export function clearDiscovery() {
  $("discovery").hidden = true;
  $("discovery-summary").textContent = "";
  $("discovery-proposals").replaceChildren();
}

// Show `found` (a FoundOutsideLibrary message) of the diagnosis of campaign `campaignId`.
export function showDiscovery(found, campaignId) {
  clearDiscovery();
  $("discovery").hidden = false;
  if (!found.available) {
    $("discovery-summary").textContent = `Nothing looked for: ${found.reason}`;
    return;
  }
  const proposals = found.proposals || [];
  const searched = (found.searched || []).map((s) =>
    `${s.torque}: residual torque RMS ${fmt(s.residual_rms, 3)} → ${fmt(s.remaining_rms, 3)} N·m ` +
    `(${s.candidates} of ${s.library} candidate functions show in the record)`);
  $("discovery-summary").textContent = (proposals.length
    ? "A proposal, not part of the campaign until you add it. "
    : "Nothing: no function of the library explains the residual torque. ") + `${searched.join("; ")}.`;
  for (const [k, p] of proposals.entries()) $("discovery-proposals").append(proposalCard(p, k, campaignId));
}

const cell = (value, digits, cls = "num") =>
  el("td", { class: cls, "data-value": String(value), text: fmt(value, digits) });

function proposalCard(p, k, campaignId) {
  const place = p.torque ? `Torque on ${p.torque}` : `Added to ${p.output}`;
  const terms = el("table", { id: `proposal-${k}-terms`, class: "terms" },
    el("caption", { text: "Terms, each with its 95% interval" }),
    el("thead", {}, el("tr", {}, ...["parameter", "function", "in words", "estimate", "95% interval", "bounds proposed"]
      .map((h) => el("th", { scope: "col", text: h })))),
    el("tbody", {}, ...p.terms.map((t) => el("tr", { "data-parameter": t.parameter },
      el("th", { scope: "row", text: t.parameter }),
      el("td", {}, el("code", { text: t.function })),
      el("td", { text: t.words }),
      cell(t.estimate, 4, "num estimate"),
      el("td", { class: "num interval", "data-low": String(t.ci_low), "data-high": String(t.ci_high), text: `[${fmt(t.ci_low, 4)}, ${fmt(t.ci_high, 4)}]` }),
      el("td", { class: "num bounds", text: `[${fmt(t.min, 4)}, ${fmt(t.max, 4)}]` })))));
  const harmonics = el("ul", { class: "harmonics" }, ...(p.harmonics || []).map((h) => el("li", {
    class: "harmonic", "data-multiple": String(h.multiple), "data-amplitude": String(h.amplitude),
    "data-low": String(h.ci_low), "data-high": String(h.ci_high),
    text: `${h.multiple} periods per turn of ${h.angle}: amplitude ${fmt(h.amplitude, 4)} N·m, ` +
      `95% interval [${fmt(h.ci_low, 4)}, ${fmt(h.ci_high, 4)}], phase ${fmt(h.phase, 3)} rad`,
  })));
  const card = el("article", { class: "proposal", id: `proposal-${k}`, "data-effect": p.name },
    el("h4", { text: `${place}: ${p.name}` }),
    el("p", {}, "In symbols: ", el("code", { class: "formula", text: p.formula })),
    el("p", { class: "formula-words", text: `In words: ${p.formula_words}.` }),
    el("p", { class: "residual", text: `Residual torque RMS on the joint ${fmt(p.residual_rms, 3)} → ${fmt(p.remaining_rms, 3)} N·m with these terms.` }),
    terms);
  if (p.harmonics && p.harmonics.length) card.append(harmonics);
  const r = p.refit;
  if (r) {
    const folded = (r.folded || []).length
      ? ` ${r.folded.join(", ")} went into the joint's own friction (the same degree of freedom) instead of the effect.` : "";
    card.append(el("p", {
      class: "refit", "data-before": String(r.objective_before), "data-after": String(r.objective_after),
      "data-ratio-before": String(r.ratio_before), "data-ratio-after": String(r.ratio_after),
      text: `Refitted with the campaign: objective ${fmt(r.objective_before, 4)} → ${fmt(r.objective_after, 4)}, ` +
        `${fmt(r.ratio_before, 4)} → ${fmt(r.ratio_after, 4)} times the noise floor (${fmt(r.noise_floor, 4)}), ` +
        `${r.evaluations} evaluations.${folded}`,
    }));
  }
  const effect = r && r.effect;
  card.append(el("p", { text: effect ? "The block the campaign gets (a campaign file takes it as it is):" : "The block to paste into a campaign file:" }),
    el("pre", { class: "toml" }, el("code", { text: effect ? r.effects_toml : p.effects_toml })));
  if (effect) {
    const accept = el("button", { type: "button", id: `proposal-${k}-accept`, text: "Add to the campaign" });
    accept.addEventListener("click", () => acceptIntoCampaign(effect, campaignId));
    card.append(el("p", {}, accept, " ",
      el("span", { class: "hint", text: "The Calibration tab's form gets the diagnosed campaign with this effect; start it there to fit it." })));
  }
  return card;
}

// The diagnosed campaign's spec in the Calibration tab's form, with `effect` added, ready
// to start as a new campaign (the diagnosed one stays as it was).
async function acceptIntoCampaign(effect, campaignId) {
  showError("diagnosis-error", "");
  try {
    const s = await call("GetCampaign", { id: campaignId });
    if (!s.campaign) {
      throw new Error("this campaign was not submitted through the page or the API: its form cannot be filled in; paste the block into its campaign file");
    }
    await fillForm(s.campaign);
    addDefinedEffect(effect);
    $("tab-calibration").click();
    $("calibration-status").textContent =
      `The form holds ${s.name} (${s.id.slice(0, 8)}) with ${effect.name} added: start it to fit the effect with the campaign's parameters.`;
    $("defined-effects").scrollIntoView({ block: "start" });
    $("defined-effects").dispatchEvent(new Event("change", { bubbles: true }));
  } catch (e) {
    showError("diagnosis-error", e.message);
  }
}
