// The table of a campaign's runs: one row per run (method × start) as the server sends them
// (CampaignState.runs: label, method, start, evaluations, rounds, iterations, termination,
// objective, parameters, whether it is at the best), sortable by any column. Runs are named
// by the server's label, the name the progress plot and the waterfall use.
import { $, RUNNING, el, fmt } from "./common.js";

// Columns: [key, heading, value of a run for sorting, cell of a run].
const COLUMNS = [
  ["label", "run", (r) => r.label, (r) => el("th", { scope: "row", text: r.label })],
  ["method", "method", (r) => r.method, (r) => el("td", { text: r.method })],
  ["start", "start", (r) => Number(r.start), (r) => el("td", { class: "num", text: String(r.start) })],
  ["evaluations", "evaluations", (r) => Number(r.evaluations),
    (r) => el("td", { class: "num", "data-value": String(r.evaluations), text: String(r.evaluations) })],
  ["rounds", "rounds", (r) => Number(r.rounds || 0),
    (r) => el("td", { class: "num", "data-value": String(r.rounds || 0), text: String(r.rounds || 0) })],
  ["iterations", "iterations", (r) => Number(r.iterations),
    (r) => el("td", { class: "num", text: r.termination ? String(r.iterations) : "—" })],
  ["termination", "termination", (r) => r.termination, (r) => el("td", { text: r.termination || (shown.phase === RUNNING ? "running" : "stopped before its end") })],
  ["objective", "objective", (r) => objective(r),
    (r) => el("td", { class: "num", "data-value": String(objective(r)), text: fmt(objective(r)) })],
  ["at_best", "at the best", (r) => (r.at_best ? 0 : 1), (r) => el("td", { class: "flag", text: r.at_best ? "at the best" : "" })],
];

const objective = (r) => (r.objective === null || r.objective === undefined ? Infinity : r.objective);

// How the table is sorted: a column's key and its direction (1 ascending, -1 descending).
const order = { key: "objective", direction: 1 };
let shown = { runs: [], names: [], phase: "CAMPAIGN_PHASE_UNSPECIFIED" };

// Show the runs of campaign state `s`, their parameters in the order `names`.
export function showRuns(s, names = []) {
  const runs = s.runs || [];
  const seen = new Set(names);
  for (const r of runs) for (const n of Object.keys(r.parameters || {})) if (!seen.has(n)) { seen.add(n); names.push(n); }
  const same = JSON.stringify([runs, names, s.phase]) === JSON.stringify([shown.runs, shown.names, shown.phase]);
  shown = { runs, names, phase: s.phase };
  $("runs").hidden = !runs.length;
  if (!same) draw();
}

function draw() {
  const { runs, names } = shown;
  const table = $("runs-table");
  const columns = [
    ...COLUMNS,
    ...names.map((n) => [`p:${n}`, n, (r) => parameter(r, n),
      (r) => el("td", { class: "num", "data-parameter": n, "data-value": String(parameter(r, n)), text: fmt(parameter(r, n), 8) })]),
  ];
  const head = el("tr");
  for (const [key, heading] of columns) {
    const sorted = order.key === key;
    const button = el("button", { type: "button", class: "sort", text: heading,
      "aria-label": `sort by ${heading}` });
    button.addEventListener("click", () => {
      order.direction = sorted ? -order.direction : 1;
      order.key = key;
      draw();
      table.querySelector(`th[data-key="${CSS.escape(key)}"] button`).focus();
    });
    head.append(el("th", { scope: "col", "data-key": key,
      "aria-sort": sorted ? (order.direction > 0 ? "ascending" : "descending") : "none" }, button));
  }
  table.tHead.replaceChildren(head);
  const value = (columns.find(([key]) => key === order.key) || COLUMNS[6])[2];
  const rows = [...runs].sort((a, b) => {
    const x = value(a), y = value(b);
    const c = typeof x === "string" ? x.localeCompare(y) : x - y || 0;
    return c * order.direction || Number(a.start) - Number(b.start);
  });
  const body = table.tBodies[0];
  body.replaceChildren();
  for (const r of rows) {
    const row = el("tr", { "data-label": r.label, class: r.at_best ? "at-best" : "" });
    for (const [, , , cell] of columns) row.append(cell(r));
    body.append(row);
  }
}

function parameter(r, name) {
  const v = (r.parameters || {})[name];
  return v === undefined || v === null ? NaN : v;
}
