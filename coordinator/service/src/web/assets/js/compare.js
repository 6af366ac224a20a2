// Campaigns side by side: the finished campaigns ticked in the list of campaigns, their
// objective and parameters in one table (as their results hold them: the best point, and
// each parameter's range over the runs that reached the best), their fit plots next to
// each other, output by output.
import { $, FINISHED, call, checkedValues, el, figure, fmt, post, request, showError } from "./common.js";

// The ids of the campaigns ticked for comparison.
export const ticked = () =>
  checkedValues("compare");

// A tick box for a finished campaign `s` in the list (kept ticked across refreshes).
export function compareBox(s, wasTicked) {
  if (s.phase !== FINISHED) return el("td");
  return el("td", {}, el("input", {
    type: "checkbox", name: "compare", value: s.id, checked: wasTicked,
    "aria-label": `compare campaign ${s.name} ${s.id.slice(0, 8)}`,
  }));
}

export async function compareTicked() {
  showError("compare-error", "");
  const ids = ticked();
  if (ids.length < 2) {
    showError("compare-error", "tick two or more finished campaigns in the list to compare them");
    return;
  }
  try {
    const states = await Promise.all(ids.map((id) => call("GetCampaign", { id })));
    showComparison(states.filter((s) => s.result));
  } catch (e) {
    showError("compare-error", e.message);
  }
}

function showComparison(states) {
  const results = states.map((s) => s.result);
  const table = $("comparison-table");
  const head = el("tr", {}, el("th", { scope: "col", text: "" }));
  for (const s of states) {
    head.append(el("th", { scope: "col", "data-campaign": s.id },
      s.name, el("br"), el("code", { text: s.id.slice(0, 12) })));
  }
  table.tHead.replaceChildren(head);
  const body = table.tBodies[0];
  body.replaceChildren();
  const row = (label, cells, attrs = {}) =>
    body.append(el("tr", attrs, el("th", { scope: "row", text: label }), ...cells));
  row("model", results.map((r) => el("td", { text: `${r.model} (version ${r.model_version})` })));
  row("objective, calibrated", results.map((r, k) =>
    el("td", { class: "num objective", "data-campaign": states[k].id, "data-value": String(r.best.objective), text: fmt(r.best.objective, 8) })),
  { "data-row": "objective" });
  row("objective at the nominal point", results.map((r) => el("td", { class: "num", text: fmt(r.nominal_objective, 8) })));
  row("best run", results.map((r) => el("td", { text: `${r.best.method}, start ${r.best.start}` })));
  row("runs that reached the best", results.map((r) =>
    el("td", { class: "num", text: `${r.runs_at_best.count} of ${r.runs_at_best.of}` })));
  const names = [];
  for (const r of results) for (const p of r.free_parameters) if (!names.includes(p.name)) names.push(p.name);
  for (const name of names) {
    const cells = results.map((r, k) => {
      const free = r.free_parameters.find((p) => p.name === name);
      if (!free) return el("td", { class: "num", text: "not calibrated" });
      const value = r.best.parameters[name];
      const range = ((r.spread || {}).parameters || {})[name];
      const cell = el("td", {
        class: "num parameter", "data-campaign": states[k].id, "data-parameter": name, "data-value": String(value),
        text: fmt(value, 8),
      });
      if (range) {
        cell.dataset.low = String(range.min);
        cell.dataset.high = String(range.max);
        cell.append(el("small", { text: `runs at the best: [${fmt(range.min, 6)}, ${fmt(range.max, 6)}]` }));
      }
      cell.append(el("small", { text: `bounds [${fmt(free.min)}, ${fmt(free.max)}]` }));
      return cell;
    });
    row(name, cells, { "data-parameter": name });
  }
  showComparedPlots(states);
  showOverlays(states);
  $("comparison").hidden = false;
  $("comparison").scrollIntoView({ block: "start" });
}

// Each output every campaign compares, its fits drawn over the measured data once
// (POST /ui/compare: the server draws, the first campaign's record and windows).
async function showOverlays(states) {
  const holder = $("comparison-overlays");
  holder.replaceChildren();
  const outputs = (s) => s.result.outputs || [];
  const shared = outputs(states[0]).filter((o) => states.every((s) => outputs(s).includes(o)));
  for (const output of shared) {
    try {
      const body = { campaigns: states.map((s) => s.id), output };
      const text = await (await request("/ui/compare", post(body), "compare")).text();
      holder.append(el("div", { class: "overlay-row", "data-output": output },
        figure(text, `${output}: ${states.map((s) => s.name).join(", ")} over the measured data`)));
    } catch (e) {
      showError("compare-error", `${output}: ${e.message}`);
    }
  }
}

// Each fit plot of the campaigns (measured, nominal and calibrated, per output), the
// campaigns' versions of one plot in one row.
function showComparedPlots(states) {
  const holder = $("comparison-plots");
  holder.replaceChildren();
  const files = [];
  for (const s of states) {
    for (const f of Object.keys(s.plots || {})) {
      if (f.endsWith(".svg") && f !== "waterfall.svg" && !files.includes(f)) files.push(f);
    }
  }
  files.sort();
  for (const f of files) {
    const what = f.replace(/\.svg$/, "");
    const line = el("div", { class: "compare-row", style: `--columns: ${states.length}`, "data-plot": f },
      el("h4", { text: `${what}: measured, nominal and calibrated` }));
    for (const s of states) {
      const svg = (s.plots || {})[f];
      line.append(svg ? figure(svg, `${s.name} (${s.id.slice(0, 8)}): ${what}`)
        : el("p", { class: "hint", text: `${s.name} has no plot of ${what}` }));
    }
    holder.append(line);
  }
}
