// Where the page is, kept in the URL's fragment so that a reload or a link finds it again:
// `#/<tab>[/campaign/<id>][/dataset/<id>]`, e.g. `#/calibration/campaign/3fa2…` or
// `#/dataset/9c01…` (the tab then follows from what the link names). The state itself (the
// campaign's spec, its progress history, its result; the dataset) is the server's: the
// page only remembers which to ask for.

const TABS = ["model", "measurement", "calibration", "diagnosis"];
const HEX = /^[0-9a-f]{64}$/;

// The route the URL names now: {tab, campaign, dataset}, each possibly empty.
export function readRoute(hash = location.hash) {
  const parts = hash.replace(/^#\/?/, "").split("/").filter((p) => p);
  const route = { tab: "", campaign: "", dataset: "" };
  for (let k = 0; k < parts.length; k++) {
    const part = decodeURIComponent(parts[k]);
    if (TABS.includes(part)) route.tab = part;
    else if ((part === "campaign" || part === "dataset") && HEX.test(parts[k + 1] || "")) {
      route[part] = parts[++k];
    }
  }
  if (!route.tab) route.tab = route.campaign ? "calibration" : route.dataset ? "measurement" : "model";
  return route;
}

// The fragment of `route`.
export function routeHash(route) {
  let hash = `#/${route.tab || "model"}`;
  if (route.campaign) hash += `/campaign/${route.campaign}`;
  if (route.dataset) hash += `/dataset/${route.dataset}`;
  return hash;
}

// Change part of the route (e.g. {tab: "calibration"}), keeping the rest; the page's
// history is not lengthened (a reload lands on the same place).
export function writeRoute(change) {
  const hash = routeHash({ ...readRoute(), ...change });
  if (hash !== location.hash) history.replaceState(null, "", hash);
}
