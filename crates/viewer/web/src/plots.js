// A correction's panels: the learning curve (R_norm over wall time and over
// samples, uPlot), the acceptance criteria with their values and limits, and
// the plausibility metrics before and after (bars, SVG).

import uPlot from "uplot";
import "uplot/dist/uPlot.min.css";

const CURVE = "#3b7cff";

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") e.className = v;
    else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c);
  return e;
}

function fmt(v) {
  if (v === null || v === undefined || Number.isNaN(v)) return "-";
  const a = Math.abs(v);
  if (a !== 0 && (a < 0.001 || a >= 1e5)) return v.toExponential(2);
  return v.toFixed(a < 1 ? 3 : a < 100 ? 2 : 0);
}

/// The learning curve of `points` ([wall_s, samples, r_norm] each) as two
/// plots in one panel; returns the panel (its `update(points)` redraws).
export function curvePanel(title, points) {
  const row = el("div", { class: "plots" });
  const panel = el("div", { class: "panel curve" }, el("h4", {}, title), row);
  const make = (xIndex, xLabel) => {
    const holder = el("div", { class: "plot", "data-x": xLabel });
    row.append(holder);
    const opts = {
      width: 340,
      height: 180,
      scales: { x: { time: false }, y: { range: [0, 1] } },
      legend: { show: false },
      series: [{ label: xLabel }, { label: "R_norm", stroke: CURVE, width: 2, points: { show: true, size: 5, fill: CURVE } }],
      axes: [{ label: xLabel, size: 40 }, { label: "R_norm", size: 45 }],
    };
    return { plot: new uPlot(opts, data(points, xIndex), holder), xIndex };
  };
  const data = (pts, xIndex) => [pts.map((p) => p[xIndex]), pts.map((p) => p[2])];
  const plots = [make(0, "wall time (s)"), make(1, "samples")];
  panel.update = (pts) => plots.forEach(({ plot, xIndex }) => plot.setData(data(pts, xIndex)));
  panel.plots = plots.map((p) => p.plot);
  return panel;
}

export function criteriaPanel(criteria, accepted, because) {
  const rows = criteria.map((c) =>
    el("tr", {},
      el("td", {}, c.name),
      el("td", {}, fmt(c.value)),
      el("td", {}, `${c.at_most ? "\u2264" : "\u2265"} ${fmt(c.limit)}`),
      el("td", { class: c.passed ? "pass" : "fail" }, c.passed ? "pass" : "fail"),
      el("td", { class: "hint" }, c.meaning || "")));
  const table = el("table", { class: "criteria" },
    el("tr", {}, el("th", {}, "criterion"), el("th", {}, "value"), el("th", {}, "limit"), el("th", {}, ""), el("th", {}, "")),
    ...rows);
  const verdict = el("p", { class: accepted ? "pass" : "fail" }, accepted ? "accepted" : `rejected: ${(because || []).join("; ")}`);
  return el("div", { class: "panel criteria" }, el("h4", {}, "Acceptance"), verdict, table);
}

/// Bars of each metric before (grey) and after (blue), each metric on its own scale.
export function plausibilityPanel(before, after) {
  const metrics = [
    ["foot skating (m/s)", "foot_skating_m_s"],
    ["penetration mean (m)", "penetration_mean_m"],
    ["penetration max (m)", "penetration_max_m"],
    ["floating (fraction)", "floating_fraction"],
    ["contact (fraction)", "contact_fraction"],
    ["jerk (m/s\u00b3)", "jerk_m_s3"],
  ].filter(([, k]) => before[k] !== undefined && after[k] !== undefined);
  const ns = "http://www.w3.org/2000/svg";
  const rowH = 34;
  const width = 380;
  const svg = document.createElementNS(ns, "svg");
  svg.setAttribute("width", width);
  svg.setAttribute("height", metrics.length * rowH + 20);
  svg.setAttribute("class", "bars");
  const add = (tag, attrs, text) => {
    const e = document.createElementNS(ns, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    svg.append(e);
  };
  metrics.forEach(([label, key], i) => {
    const y = i * rowH;
    const b = before[key];
    const a = after[key];
    const top = Math.max(Math.abs(b), Math.abs(a), 1e-12);
    add("text", { x: 0, y: y + 11, "font-size": 11 }, label);
    [[b, "#9aa0aa", "before"], [a, CURVE, "after"]].forEach(([v, color, which], k) => {
      const w = (Math.abs(v) / top) * 220;
      add("rect", { x: 90, y: y + 14 + k * 9, width: Math.max(w, 1), height: 8, fill: color, "data-metric": key, "data-which": which });
      add("text", { x: 95 + w, y: y + 21 + k * 9, "font-size": 9 }, fmt(v));
    });
  });
  add("text", { x: 0, y: metrics.length * rowH + 14, "font-size": 10, fill: "#667" }, "grey: before correction, blue: after");
  return el("div", { class: "panel plausibility" }, el("h4", {}, "Plausibility before / after"), svg);
}

/// Every panel for a correction: from its full report when there is one, else
/// from the manifest's summary.
export function correctionPanels(report, summary) {
  const out = [];
  if (report) {
    out.push(curvePanel(`Learning curve: ${report.source}`, report.curve || []));
    out.push(criteriaPanel(report.criteria || [], report.accepted, report.rejected_because));
    out.push(plausibilityPanel(report.plausibility_before, report.plausibility_after));
  } else if (summary) {
    out.push(criteriaPanel(summary.criteria || [], summary.accepted, summary.rejected_because));
    out.push(plausibilityPanel(
      { foot_skating_m_s: summary.foot_skating_before_m_s, penetration_mean_m: summary.penetration_before_m, floating_fraction: summary.floating_before },
      { foot_skating_m_s: summary.foot_skating_after_m_s, penetration_mean_m: summary.penetration_after_m, floating_fraction: summary.floating_after }));
  }
  return out;
}
