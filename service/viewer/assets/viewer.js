// Draws the scene JSON embedded in the page with plotly.js and keeps it current.
// The Python side (service/viewer/scene.py) prepares every coordinate; this file only renders.
"use strict";

const plot = document.getElementById("plot");
const rows = document.getElementById("grasp-rows");
const statusLine = document.getElementById("status");
const shading = document.getElementById("shading");
let scene = JSON.parse(document.getElementById("scene").textContent);
let selectedRank = null;

function qualityColour(quality, low) {
  // Red at the threshold, green at 1: the same scale as the grasp outlines.
  const t = Math.max(0, Math.min(1, (quality - low) / Math.max(1e-6, 1 - low)));
  return `hsl(${Math.round(120 * t)}, 80%, 40%)`;
}

function cloudTrace() {
  const pts = scene.cloud.points;
  const marker = { size: 2 };
  if (shading.value === "normal") {
    marker.color = scene.cloud.normals.map(
      (n) => `rgb(${n.map((v) => Math.round(127.5 * (v + 1))).join(",")})`
    );
  } else {
    marker.color = pts.map((p) => p[2]);
    marker.colorscale = "Viridis";
  }
  return {
    type: "scatter3d", mode: "markers", name: `surface (${scene.cloud.total} points)`,
    x: pts.map((p) => p[0]), y: pts.map((p) => p[1]), z: pts.map((p) => p[2]),
    marker, hoverinfo: "skip",
  };
}

function polyline(path, name, line, extra) {
  return Object.assign({
    type: "scatter3d", mode: "lines", name, line,
    x: path.map((p) => (p ? p[0] : null)),
    y: path.map((p) => (p ? p[1] : null)),
    z: path.map((p) => (p ? p[2] : null)),
  }, extra || {});
}

function graspTraces() {
  const low = scene.threshold || 0;
  const path = [], colours = [], labels = [], ranks = [];
  for (const g of scene.grasps) {
    for (const p of g.outline.concat([null])) {
      path.push(p);
      colours.push(qualityColour(g.quality, low));
      labels.push(`#${g.rank} quality ${g.quality.toFixed(3)}, width ${(1000 * g.width).toFixed(1)} mm`);
      ranks.push(g.rank);
    }
  }
  const traces = [polyline(path, `grasps (${scene.grasps.length})`, { color: colours, width: 4 },
    { text: labels, customdata: ranks, hoverinfo: "text" })];
  const chosen = scene.grasps.find((g) => g.rank === selectedRank);
  if (chosen) {
    traces.push(polyline(chosen.outline, `selected #${chosen.rank}`, { color: "#e000b0", width: 12 },
      { hoverinfo: "skip" }));
  }
  return traces;
}

function layout() {
  return {
    uirevision: scene.session_id, // keeps the user's camera across refreshes
    margin: { l: 0, r: 0, t: 0, b: 0 },
    showlegend: true, legend: { x: 0, y: 1 },
    scene: {
      aspectmode: "data",
      xaxis: { title: { text: "x (m)" } }, yaxis: { title: { text: "y (m)" } }, zaxis: { title: { text: "z (m)" } },
    },
  };
}

function traces() {
  return [cloudTrace(), polyline(scene.workspace_edges, "workspace", { color: "#888", width: 2 },
    { hoverinfo: "skip" })].concat(graspTraces());
}

function renderList() {
  const low = scene.threshold || 0;
  rows.replaceChildren(...scene.grasps.map((g) => {
    const row = document.createElement("tr");
    row.dataset.rank = g.rank;
    if (g.rank === selectedRank) row.classList.add("selected");
    const swatch = `<span class="swatch" style="background:${qualityColour(g.quality, low)}"></span>`;
    row.innerHTML = `<td>${g.rank}</td><td>${swatch}${g.quality.toFixed(3)}</td>` +
      `<td>${(1000 * g.width).toFixed(1)}</td><td>${g.tilt_deg.toFixed(1)}</td>`;
    row.addEventListener("click", () => select(g.rank === selectedRank ? null : g.rank));
    return row;
  }));
}

function renderStatus(note) {
  const parts = [
    `${scene.frame_count} frames, ${scene.cloud.total} surface points (${scene.cloud.points.length} drawn)`,
    `planner ${scene.planner}${scene.model ? ` (${scene.model})` : ""}, threshold ${scene.threshold ?? "-"}`,
    `${scene.grasps.length} grasps` + (scene.planning_ms != null ? ` in ${scene.planning_ms.toFixed(0)} ms` : ""),
  ];
  statusLine.innerHTML = parts.map((p) => `<div>${p}</div>`).join("");
  for (const message of [scene.planning_error, note]) {
    if (message) {
      const line = document.createElement("div");
      line.className = "error";
      line.textContent = message;
      statusLine.appendChild(line);
    }
  }
}

function select(rank) {
  selectedRank = rank;
  renderList();
  Plotly.react(plot, traces(), layout());
  const row = rows.querySelector(`tr[data-rank="${rank}"]`);
  if (row) row.scrollIntoView({ block: "nearest" });
}

function render(note) {
  renderStatus(note);
  renderList();
  return Plotly.react(plot, traces(), layout(), { responsive: true, displaylogo: false });
}

async function poll(seconds) {
  // A cheap session read each time; the costly re-plan only when the frame count changed.
  const base = location.pathname.replace(/\/view$/, "");
  try {
    const info = await fetch(base, { credentials: "same-origin" });
    if (!info.ok) throw new Error(`session: HTTP ${info.status}`);
    const { frame_count } = await info.json();
    if (frame_count !== scene.frame_count) {
      const answer = await fetch(`${location.pathname}/data${location.search}`, { credentials: "same-origin" });
      if (!answer.ok) throw new Error(`view data: HTTP ${answer.status}`);
      scene = await answer.json();
      if (!scene.grasps.some((g) => g.rank === selectedRank)) selectedRank = null;
      await render();
    }
    setTimeout(() => poll(seconds), seconds * 1000);
  } catch (error) {
    renderStatus(`live refresh stopped: ${error.message}`);
  }
}

shading.addEventListener("change", () => Plotly.react(plot, traces(), layout()));
render().then(() => {
  plot.on("plotly_click", (event) => {
    const rank = event.points[0] && event.points[0].customdata;
    if (rank) select(rank);
  });
  document.body.dataset.rendered = "true";
  const refresh = scene.query.refresh;
  if (refresh > 0 && location.protocol.startsWith("http")) setTimeout(() => poll(refresh), refresh * 1000);
});
