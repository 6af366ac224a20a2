// Effects defined by a formula in the Calibration tab's campaign (Campaign.defined_effects,
// the `[[effects]]` entries of a campaign file with a `formula`): listed above the
// parameters, sent with the campaign, each removable. A diagnosis' proposal is added here.
import { $, app, el, fmt } from "./common.js";

// The form's list replaced by `list` (DefinedEffect messages), e.g. a reopened campaign's.
export function setDefinedEffects(list) {
  app.definedEffects = (list || []).map((e) => ({ ...e }));
  renderDefinedEffects();
}

// Add `effect` to the form; one of the same name is replaced.
export function addDefinedEffect(effect) {
  app.definedEffects = app.definedEffects.filter((e) => e.name !== effect.name);
  app.definedEffects.push({ ...effect });
  renderDefinedEffects();
}

export function renderDefinedEffects() {
  const list = $("defined-effect-list");
  list.replaceChildren();
  for (const [k, e] of app.definedEffects.entries()) {
    const place = e.torque ? `a torque on ${e.torque}` : `a term added to ${e.output}`;
    const remove = el("button", { type: "button", class: "secondary", id: `defined-${k}-remove`, text: "Remove", "aria-label": `remove the effect ${e.name}` });
    remove.addEventListener("click", () => {
      app.definedEffects.splice(k, 1);
      renderDefinedEffects();
      // The form changed: the server checks it again.
      $("defined-effects").dispatchEvent(new Event("change", { bubbles: true }));
    });
    const rows = (e.parameters || []).map((p) => el("tr", { "data-parameter": `${e.name}.${p.name}` },
      el("th", { scope: "row", text: `${e.name}.${p.name}` }),
      el("td", { class: "num", text: fmt(p.nominal === undefined || p.nominal === null ? 0 : p.nominal, 5) }),
      el("td", { class: "num", text: fmt(p.min, 5) }),
      el("td", { class: "num", text: fmt(p.max, 5) }),
      el("td", { text: p.fixed || e.fixed ? "held at its start" : "calibrated" })));
    list.append(el("div", { class: "defined-effect", id: `defined-${k}`, "data-effect": e.name },
      el("p", {}, el("strong", { text: e.name }), `, ${place}: `, el("code", { class: "formula", text: e.formula })),
      el("table", {},
        el("caption", { class: "visually-hidden", text: `parameters of ${e.name}` }),
        el("thead", {}, el("tr", {}, ...["parameter", "start", "min", "max", ""].map((h) => el("th", { scope: "col", text: h })))),
        el("tbody", {}, ...rows)),
      el("p", {}, remove)));
  }
  $("defined-effects").hidden = !app.definedEffects.length;
}
