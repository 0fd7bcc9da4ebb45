"use strict";
/*
 * The teacher service's live dashboard. Both pages poll the service's public JSON API and redraw
 * in place; when a poll fails the last picture stays on screen under a banner and polling goes on,
 * so a restarting service comes back without a page reload.
 */

const POLL_MS = 2500;
const FETCH_TIMEOUT_MS = 5000;
const ROLLING_EPISODES = 50; // window of the reward and success rolling means
const SCATTER_RESULTS = 1000; // newest results drawn in the task space
const DIFFICULTY_RESULTS = 300; // newest results placed on the difficulty strips
const DIFFICULTY_BINS = 20;
const ELLIPSE_SIGMAS = 2;
const FIT_ROWS = 12; // newest fits listed

const REWARD_SCALE = "Viridis";
const ALP_SCALE = [[0, "#fca5a5"], [0.5, "#ef4444"], [1, "#7f1d1d"]];
const INK = "#1f2937";
const MUTED = "#6b7280";
const GRID = "#e5e7eb";

const PLOT_CONFIG = {
  displaylogo: false,
  responsive: true,
  modeBarButtonsToRemove: ["select2d", "lasso2d", "toImage"],
};

const root = document.body.dataset.root;
const api = document.body.dataset.api;

/* ---------- polling ---------- */

class HttpError extends Error {
  constructor(status, detail) {
    super(detail ? `HTTP ${status}: ${detail}` : `HTTP ${status}`);
    this.status = status;
  }
}

async function fetchJson(url) {
  const controller = new AbortController();
  const timer = setTimeout(() => controller.abort(), FETCH_TIMEOUT_MS);
  try {
    const response = await fetch(url, { signal: controller.signal, cache: "no-store" });
    if (!response.ok) {
      const body = await response.json().catch(() => ({}));
      throw new HttpError(response.status, typeof body.detail === "string" ? body.detail : "");
    }
    return await response.json();
  } finally {
    clearTimeout(timer);
  }
}

/** Fetch `url` every POLL_MS and hand each answer to `render`; `describeFailure` words the banner. */
function poll(url, render, describeFailure) {
  const tick = async () => {
    let answer = null;
    try {
      answer = await fetchJson(url);
      showBanner(null);
    } catch (error) {
      showBanner(describeFailure(error));
    }
    try {
      if (answer !== null) {
        render(answer);
        document.getElementById("updated").textContent = `updated ${clock(Date.now() / 1000)}`;
      }
    } finally {
      setTimeout(tick, POLL_MS);
    }
  };
  tick();
}

function unreachable(error) {
  return error instanceof HttpError
    ? `teacher answered ${error.message} — retrying`
    : "teacher unreachable — retrying";
}

function showBanner(message) {
  const banner = document.getElementById("banner");
  banner.hidden = message === null;
  banner.textContent = message ?? "";
}

/* ---------- formatting ---------- */

function clock(unixSeconds) {
  return new Date(unixSeconds * 1000).toLocaleTimeString([], { hour12: false });
}

function dateTime(unixSeconds) {
  const date = new Date(unixSeconds * 1000);
  const pad = (n) => String(n).padStart(2, "0");
  return `${date.getFullYear()}-${pad(date.getMonth() + 1)}-${pad(date.getDate())} ${clock(unixSeconds)}`;
}

function formatNumber(value) {
  if (typeof value !== "number") return JSON.stringify(value);
  if (Number.isInteger(value)) return value.toLocaleString("en-US");
  const magnitude = Math.abs(value);
  return magnitude !== 0 && (magnitude < 1e-3 || magnitude >= 1e5) ? value.toExponential(2) : String(+value.toPrecision(4));
}

function formatValue(value) {
  if (value === null) return "none";
  if (Array.isArray(value)) return `[${value.map(formatValue).join(", ")}]`;
  if (typeof value === "object") {
    return `{${Object.entries(value).map(([key, v]) => `${key}: ${formatValue(v)}`).join(", ")}}`;
  }
  return formatNumber(value);
}

function ago(unixSeconds) {
  const seconds = Math.max(0, Date.now() / 1000 - unixSeconds);
  if (seconds < 90) return `${Math.round(seconds)} s ago`;
  if (seconds < 5400) return `${Math.round(seconds / 60)} min ago`;
  return `${(seconds / 3600).toFixed(1)} h ago`;
}

function setText(id, text) {
  document.getElementById(id).textContent = text;
}

function rgb(hex) {
  return [0, 1, 2].map((i) => parseInt(hex.slice(1 + 2 * i, 3 + 2 * i), 16));
}

/** The colour at `fraction` (0..1) along a scale of [stop, "#rrggbb"] pairs, as "#rrggbb". Line
 * traces cannot take a colour scale, so ellipses are coloured with this. */
function scaleColour(scale, fraction) {
  const f = Math.min(1, Math.max(0, Number.isFinite(fraction) ? fraction : 0));
  const upper = scale.findIndex(([stop]) => stop >= f);
  if (upper <= 0) return scale[Math.max(upper, 0)][1];
  const [stopA, hexA] = scale[upper - 1];
  const [stopB, hexB] = scale[upper];
  const t = (f - stopA) / (stopB - stopA);
  const [from, to] = [rgb(hexA), rgb(hexB)];
  const mixed = from.map((channel, i) => Math.round(channel + t * (to[i] - channel)));
  return `#${mixed.map((c) => c.toString(16).padStart(2, "0")).join("")}`;
}

function withAlpha(hex, alpha) {
  return `rgba(${rgb(hex).join(", ")}, ${alpha})`;
}

function baseLayout(extra) {
  return {
    font: { family: "system-ui, -apple-system, 'Segoe UI', Roboto, 'DejaVu Sans', sans-serif", size: 12, color: INK },
    paper_bgcolor: "rgba(0,0,0,0)",
    plot_bgcolor: "#fbfbfc",
    margin: { l: 56, r: 16, t: 8, b: 44 },
    showlegend: false,
    hoverlabel: { font: { family: "ui-monospace, 'DejaVu Sans Mono', monospace", size: 12 } },
    ...extra,
  };
}

function axis(title, extra) {
  return { title: { text: title, font: { color: MUTED } }, gridcolor: GRID, zeroline: false, linecolor: GRID, ...extra };
}

/* ---------- the curricula list ---------- */

/** Says why fits stopped, if they did; the service stops them all at once, so one reason covers every curriculum. */
function showFitsStopped(reason) {
  const alert = document.getElementById("fits-stopped");
  alert.hidden = !reason;
  alert.textContent = reason ? `No fits run: ${reason}. Tasks still come from each teacher's last model.` : "";
}

/** Says why the database refuses writes, while it does (a full disk); the whole service shares one database. */
function showWritesFailing(reason) {
  const alert = document.getElementById("writes-failing");
  alert.hidden = !reason;
  alert.textContent = reason
    ? `The teacher's database refuses writes: ${reason}. New tasks and results wait (answered 503) until there is room.`
    : "";
}

function renderCurricula(list) {
  showFitsStopped(list.curricula.map((c) => c.counters.fits_stopped).find((reason) => reason) ?? null);
  showWritesFailing(list.curricula.map((c) => c.counters.writes_failing).find((reason) => reason) ?? null);
  const rows = document.getElementById("curricula-rows");
  rows.replaceChildren(
    ...list.curricula.map((curriculum) => {
      const counters = curriculum.counters;
      const link = document.createElement("a");
      link.href = `${root}/curricula/${encodeURIComponent(curriculum.name)}`;
      link.textContent = curriculum.name;
      const cells = [
        [link, ""],
        [curriculum.config.teacher, ""],
        [formatNumber(counters.tasks_issued), "number"],
        [formatNumber(counters.results_received), "number"],
        [counters.results_per_second.toFixed(1), "number"],
        [formatNumber(counters.fits_completed), "number"],
        [counters.last_fit_at === null ? "–" : ago(counters.last_fit_at), ""],
        [dateTime(curriculum.created_at), ""],
      ];
      const row = document.createElement("tr");
      for (const [content, className] of cells) {
        const cell = document.createElement("td");
        cell.className = className;
        cell.append(content);
        row.append(cell);
      }
      return row;
    }),
  );
  document.getElementById("empty").hidden = list.curricula.length > 0;
}

/* ---------- one curriculum ---------- */

const view = { state: null, dimensions: [] };

function renderCurriculum(state) {
  view.state = state;
  const space = state.curriculum.config.space;
  if (view.dimensions.join() !== space.map((p) => p.name).join()) setUpDimensions(space);
  renderSummary(state);
  renderProgress(state.recent_results);
  renderTaskSpace();
  renderAlp(state);
  renderDifficulty(state);
  renderFits(state);
  renderTeacherState(state);
}

function setUpDimensions(space) {
  view.dimensions = space.map((p) => p.name);
  for (const [id, index] of [["dim-x", 0], ["dim-y", Math.min(1, space.length - 1)]]) {
    const select = document.getElementById(id);
    select.replaceChildren(...view.dimensions.map((name) => new Option(name, name)));
    select.value = view.dimensions[index];
  }
  document.getElementById("dim-y").closest("label").hidden = space.length === 1;  // nothing to plot it against
}

function renderSummary(state) {
  const { config, counters } = state.curriculum;
  setText("kind", config.teacher);
  setText("stat-tasks", formatNumber(counters.tasks_issued));
  setText("stat-results", formatNumber(counters.results_received));
  setText("stat-rate", counters.results_per_second.toFixed(1));
  setText(
    "stat-outstanding",
    counters.tasks_expired
      ? `${formatNumber(counters.tasks_outstanding)} (${formatNumber(counters.tasks_expired)} expired)`
      : formatNumber(counters.tasks_outstanding),
  );
  setText(
    "stat-fits",
    counters.fits_pending ? `${formatNumber(counters.fits_completed)} (+${counters.fits_pending})` : formatNumber(counters.fits_completed),
  );
  const refit = document.getElementById("stat-refit");
  if (counters.last_fit_at === null) {
    refit.textContent = "–";
    refit.title = "";
  } else {
    const last = state.fits[state.fits.length - 1];
    refit.textContent = ago(counters.last_fit_at);
    refit.title = `at ${clock(counters.last_fit_at)}${last ? `, took ${last.duration_s.toFixed(2)} s` : ""}`;
  }
  const entries = { seed: config.seed, ...(state.teacher.params ?? config.params) };
  document.getElementById("params").replaceChildren(
    ...Object.entries(entries).map(([name, value]) => {
      const item = document.createElement("div");
      const term = document.createElement("dt");
      const detail = document.createElement("dd");
      term.textContent = name;
      detail.textContent = formatValue(value);
      item.append(term, detail);
      return item;
    }),
  );
}

/** Trailing mean over up to `window` values, skipping nulls; null where no value is in reach. */
function rollingMean(values, window) {
  const means = [];
  let sum = 0;
  let count = 0;
  values.forEach((value, i) => {
    if (value !== null) {
      sum += value;
      count += 1;
    }
    const leaving = values[i - window];
    if (i >= window && leaving !== null && leaving !== undefined) {
      sum -= leaving;
      count -= 1;
    }
    means.push(count ? sum / count : null);
  });
  return means;
}

function renderProgress(results) {
  const total = view.state.curriculum.counters.results_received;
  const episodes = results.map((_, i) => total - results.length + i + 1);
  const rewards = results.map((r) => r.reward);
  const successes = results.map((r) => (r.success === null ? null : Number(r.success)));
  const hasSuccess = successes.some((s) => s !== null);
  setText("progress-note", `rolling means over ${ROLLING_EPISODES} episodes, last ${results.length} results`);
  const traces = [
    {
      meta: "rewards", name: "reward", x: episodes, y: rewards, type: "scatter", mode: "markers",
      marker: { size: 3, color: "rgba(37, 99, 235, 0.18)" }, hovertemplate: "episode %{x}<br>reward %{y:.3f}<extra></extra>",
    },
    {
      meta: "reward-mean", name: "mean reward", x: episodes, y: rollingMean(rewards, ROLLING_EPISODES), type: "scatter",
      mode: "lines", line: { color: "#2563eb", width: 2.5 }, hovertemplate: "episode %{x}<br>mean reward %{y:.3f}<extra></extra>",
    },
  ];
  if (hasSuccess) {
    traces.push({
      meta: "success-rate", name: "success rate", x: episodes, y: rollingMean(successes, ROLLING_EPISODES), yaxis: "y2",
      type: "scatter", mode: "lines", line: { color: "#16a34a", width: 2.5 },
      hovertemplate: "episode %{x}<br>success %{y:.0%}<extra></extra>",
    });
  }
  const layout = baseLayout({
    margin: { l: 56, r: hasSuccess ? 56 : 16, t: 28, b: 44 },
    showlegend: true,
    legend: { orientation: "h", x: 0, y: 1.12, font: { color: MUTED } },
    xaxis: axis("episode"),
    yaxis: axis("reward"),
    uirevision: "progress",
  });
  if (hasSuccess) {
    layout.yaxis2 = axis("success rate", {
      overlaying: "y", side: "right", range: [0, 1], tickmode: "linear", tick0: 0, dtick: 0.25,
      tickformat: ".0%", showgrid: false,
    });
  }
  Plotly.react("progress-plot", traces, layout, PLOT_CONFIG);
}

/** Points of the `sigmas` ellipse of a 2-D Gaussian, from the eigenvectors of its covariance. */
function ellipse(centre, varX, varY, covXY, sigmas) {
  const half = (varX - varY) / 2;
  const radius = Math.hypot(half, covXY);
  const major = Math.max((varX + varY) / 2 + radius, 0);
  const minor = Math.max((varX + varY) / 2 - radius, 0);
  const angle = 0.5 * Math.atan2(2 * covXY, varX - varY);
  const [a, b] = [sigmas * Math.sqrt(major), sigmas * Math.sqrt(minor)];
  const xs = [];
  const ys = [];
  for (let i = 0; i <= 72; i += 1) {
    const t = (2 * Math.PI * i) / 72;
    const [u, v] = [a * Math.cos(t), b * Math.sin(t)];
    xs.push(centre[0] + u * Math.cos(angle) - v * Math.sin(angle));
    ys.push(centre[1] + u * Math.sin(angle) + v * Math.cos(angle));
  }
  return [xs, ys];
}

function renderTaskSpace() {
  const state = view.state;
  const space = state.curriculum.config.space;
  if (space.length === 1) {
    renderOneParameter(state, space[0]);
    return;
  }
  const xName = document.getElementById("dim-x").value;
  const yName = document.getElementById("dim-y").value;
  const [xIndex, yIndex] = [xName, yName].map((name) => view.dimensions.indexOf(name));
  const results = state.recent_results.slice(-SCATTER_RESULTS);
  const components = state.teacher.components ?? [];
  const alps = components.map((c) => c.mean_alp ?? 0);
  const alpMax = Math.max(1e-9, ...alps);

  const origins = state.teacher.recent_task_origins;
  const share = (origin) => origins.filter((o) => o === origin).length / origins.length;
  const shares = origins && origins.length
    ? ` · ${Math.round(100 * share("gmm"))}% of recent tasks from the GMM`
      + (origins.includes("target") ? `, ${Math.round(100 * share("target"))}% on the hardest task` : "")
    : "";
  setText("space-note", `last ${results.length} results${shares}`);

  const traces = components.map((component, k) => {
    const cov = component.covariance;
    const [xs, ys] = ellipse(
      [component.mean[xName], component.mean[yName]],
      cov[xIndex][xIndex], cov[yIndex][yIndex], cov[xIndex][yIndex], ELLIPSE_SIGMAS,
    );
    const colour = scaleColour(ALP_SCALE, alps[k] / alpMax);
    return {
      meta: "ellipse", name: `component ${k + 1}`, x: xs, y: ys, type: "scatter", mode: "lines",
      line: { color: colour, width: 1.5 + 2 * (alps[k] / alpMax) }, fill: "toself",
      fillcolor: withAlpha(colour, 0.05), hoverinfo: "skip",
    };
  });
  traces.unshift(...stateBackdrop(state.teacher, xName, yName));
  traces.push({
    meta: "tasks", name: "tasks", type: "scatter", mode: "markers",
    x: results.map((r) => r.params[xName]), y: results.map((r) => r.params[yName]),
    customdata: results.map((r) => r.reward),
    marker: {
      size: 6, opacity: 0.8, color: results.map((r) => r.reward), colorscale: REWARD_SCALE,
      colorbar: { title: { text: "reward", side: "right" }, x: 1.0, xpad: 8, thickness: 12, len: 0.9 },
    },
    hovertemplate: `${xName} %{x:.3f}<br>${yName} %{y:.3f}<br>reward %{customdata:.3f}<extra></extra>`,
  });
  if (components.length) {
    traces.push({
      meta: "means", name: "component means", type: "scatter", mode: "markers+text",
      x: components.map((c) => c.mean[xName]), y: components.map((c) => c.mean[yName]),
      text: components.map((_, k) => String(k + 1)), textposition: "top center",
      textfont: { color: INK, size: 12 },
      customdata: components.map((c) => [c.mean_alp, c.weight]),
      marker: {
        symbol: "x-thin", size: 11, line: { width: 2.5, color: alps.map((a) => scaleColour(ALP_SCALE, a / alpMax)) },
        color: alps, cmin: 0, cmax: alpMax, colorscale: ALP_SCALE,
        colorbar: { title: { text: "mean ALP", side: "right" }, x: 1.13, xpad: 8, thickness: 12, len: 0.9 },
      },
      hovertemplate: "component %{text}<br>mean ALP %{customdata[0]:.3f}<br>weight %{customdata[1]:.2f}<extra></extra>",
    });
  }
  traces.push(...stateMarks(state.teacher, xName, yName));
  const range = (name) => {
    const p = space.find((q) => q.name === name);
    const pad = 0.04 * (p.high - p.low || 1);
    return [p.low - pad, p.high + pad];
  };
  Plotly.react(
    "space-plot",
    traces,
    baseLayout({
      margin: { l: 60, r: 8, t: 8, b: 48 },
      xaxis: axis(xName, { range: range(xName) }),
      yaxis: axis(yName, { range: range(yName) }),
      uirevision: `${xName}/${yName}`,
    }),
    PLOT_CONFIG,
  );
}

/** The key of a task's values in the space's order: recent results and a level table's rows are matched by it. */
function taskKey(space, task) {
  return space.map((p) => task[p.name]).join(",");
}

/** Per task of ``results``: how many came back, how many say whether they succeeded and how many did, and their
 *  reward's sum, keyed by ``taskKey``. */
function resultsPerTask(space, results) {
  const tally = new Map();
  for (const result of results) {
    const key = taskKey(space, result.params);
    const entry = tally.get(key) ?? { results: 0, told: 0, successes: 0, reward: 0 };
    entry.results += 1;
    entry.reward += result.reward;
    if (result.success !== null && result.success !== undefined) {
      entry.told += 1;
      entry.successes += Number(result.success);
    }
    tally.set(key, entry);
  }
  return tally;
}

/** "12 recent results<br>success 50%<br>mean reward 0.41": a task's tally as hover lines. */
function tallyText(entry) {
  if (!entry) return "no recent results";
  const success = entry.told ? `<br>success ${Math.round((100 * entry.successes) / entry.told)}%` : "";
  return `${formatNumber(entry.results)} recent results${success}<br>mean reward ${formatValue(entry.reward / entry.results)}`;
}

/** A space of one parameter, drawn on its own axis rather than against itself: over a level space (one integer
 *  parameter) each level's recent results as a bar and its success rate as a dot, its teacher's score and chance on
 *  hover where the teacher lists the level; over one float parameter, recent results' rewards along it. */
function renderOneParameter(state, parameter) {
  const name = parameter.name;
  const results = state.recent_results.slice(-SCATTER_RESULTS);
  const xaxis = axis(name, parameter.type === "integer" ? {} : { range: [parameter.low, parameter.high] });
  if (parameter.type !== "integer") {
    setText("space-note", `last ${results.length} results`);
    Plotly.react(
      "space-plot",
      [{
        meta: "tasks", name: "tasks", type: "scatter", mode: "markers",
        x: results.map((r) => r.params[name]), y: results.map((r) => r.reward),
        marker: { size: 6, opacity: 0.8, color: results.map((r) => r.reward), colorscale: REWARD_SCALE },
        hovertemplate: `${name} %{x:.3f}<br>reward %{y:.3f}<extra></extra>`,
      }],
      baseLayout({ margin: { l: 60, r: 8, t: 8, b: 48 }, xaxis, yaxis: axis("reward"), uirevision: name }),
      PLOT_CONFIG,
    );
    return;
  }
  const space = [parameter];
  const tally = resultsPerTask(space, results);
  const listed = new Map((state.teacher.levels ?? []).map((row) => [taskKey(space, row.task), row]));
  const values = [...tally.keys()].map(Number).sort((a, b) => a - b);
  const hover = values.map((value) => {
    const row = listed.get(String(value));
    const teacherLines = row
      ? Object.entries(row).filter(([column]) => !["task", "level"].includes(column))
        .map(([column, v]) => `<br>${column} ${formatValue(v)}`).join("")
      : "";
    const level = row && row.level !== value ? ` (level ${row.level})` : "";
    return `${name} ${value}${level}<br>${tallyText(tally.get(String(value)))}${teacherLines}`;
  });
  const rates = values.map((value) => {
    const entry = tally.get(String(value));
    return entry.told ? entry.successes / entry.told : null;
  });
  setText("space-note", `last ${results.length} results over ${formatNumber(values.length)} ${name}s`);
  Plotly.react(
    "space-plot",
    [
      {
        meta: "level-results", name: "recent results", type: "bar", marker: { color: "#93c5fd" },
        x: values, y: values.map((value) => tally.get(String(value)).results),
        text: hover, textposition: "none", hovertemplate: "%{text}<extra></extra>",
      },
      {
        meta: "level-success", name: "success rate", type: "scatter", mode: "markers", yaxis: "y2",
        x: values, y: rates, marker: { size: 6, color: "#16a34a" }, text: hover, hovertemplate: "%{text}<extra></extra>",
      },
    ],
    baseLayout({
      margin: { l: 60, r: 56, t: 8, b: 48 },
      xaxis,
      yaxis: axis("recent results", { rangemode: "tozero" }),
      yaxis2: axis("success rate", { overlaying: "y", side: "right", range: [0, 1.05], dtick: 0.25, tickformat: ".0%" }),
      bargap: 0.1,
      showlegend: false,
      uirevision: name,
    }),
    PLOT_CONFIG,
  );
}

function renderAlp(state) {
  const components = (state.teacher.components ?? []).filter((c) => c.mean_alp !== undefined);
  const empty = document.getElementById("alp-empty");
  const plot = document.getElementById("alp-plot");
  if (!components.length) {
    empty.hidden = false;
    plot.hidden = true;
    const bootstrapTasks =
      state.curriculum.config.params.bootstrap_spread == null ? "uniform tasks" : "tasks near the easiest";
    empty.textContent =
      state.curriculum.config.teacher === "alp-gmm"
        ? `Bootstrapping on ${bootstrapTasks}; the first fit comes at ${formatNumber(state.teacher.next_fit_at_results)} results.`
        : `The ${state.curriculum.config.teacher} teacher measures no learning progress per component.`;
    return;
  }
  empty.hidden = true;
  plot.hidden = false;
  const alps = components.map((c) => c.mean_alp);
  const alpMax = Math.max(1e-9, ...alps);
  Plotly.react(
    plot,
    [{
      meta: "alp", type: "bar", x: components.map((_, k) => String(k + 1)), y: alps,
      marker: { color: alps.map((a) => scaleColour(ALP_SCALE, a / alpMax)) },
      customdata: components.map((c) => [c.weight, c.sampling_probability ?? null]),
      hovertemplate: "component %{x}<br>mean ALP %{y:.3f}<br>weight %{customdata[0]:.2f}<br>sampled %{customdata[1]:.0%}<extra></extra>",
    }],
    baseLayout({
      margin: { l: 52, r: 8, t: 8, b: 40 },
      xaxis: axis("component", { type: "category" }),
      yaxis: axis("mean ALP", { rangemode: "tozero" }),
      bargap: 0.35,
      uirevision: "alp",
    }),
    PLOT_CONFIG,
  );
}

/** Map a value onto 0 (easiest) .. 1 (hardest) using the space's anchors when it has them. */
function difficulty(parameter, value) {
  const anchored = parameter.easiest !== null && parameter.hardest !== null && parameter.easiest !== parameter.hardest;
  const [easy, hard] = anchored ? [parameter.easiest, parameter.hardest] : [parameter.low, parameter.high];
  return hard === easy ? 0 : Math.min(1, Math.max(0, (value - easy) / (hard - easy)));
}

function renderDifficulty(state) {
  const space = state.curriculum.config.space;
  const results = state.recent_results.slice(-DIFFICULTY_RESULTS);
  const names = space.map((p) => p.name);
  const shares = space.map((parameter) => {
    const counts = new Array(DIFFICULTY_BINS).fill(0);
    for (const result of results) {
      const d = difficulty(parameter, result.params[parameter.name]);
      counts[Math.min(DIFFICULTY_BINS - 1, Math.floor(d * DIFFICULTY_BINS))] += 1;
    }
    return counts.map((c) => (results.length ? c / results.length : 0));
  });
  const binCentres = Array.from({ length: DIFFICULTY_BINS }, (_, i) => (i + 0.5) / DIFFICULTY_BINS);
  const anchorsText = space.map((p) => {
    const anchored = p.easiest !== null && p.hardest !== null && p.easiest !== p.hardest;
    return anchored ? `0 = ${formatNumber(p.easiest)}, 1 = ${formatNumber(p.hardest)}` : `0 = low ${formatNumber(p.low)}, 1 = high ${formatNumber(p.high)}`;
  });
  const traces = [
    {
      meta: "difficulty", type: "heatmap", showlegend: false, x: binCentres, y: names, z: shares, zmin: 0,
      colorscale: [[0, "#f8fafc"], [0.15, "#bfdbfe"], [1, "#1e3a8a"]],
      customdata: names.map((_, row) => binCentres.map(() => anchorsText[row])),
      colorbar: { title: { text: "share", side: "right" }, thickness: 12, tickformat: ".0%" },
      xgap: 1, ygap: 4,
      hovertemplate: "%{y}: %{z:.0%} of recent tasks near %{x:.2f}<br>(%{customdata})<extra></extra>",
    },
  ];
  if (results.length) {
    traces.push({
      meta: "difficulty-mean", name: "mean of recent tasks", type: "scatter", mode: "markers", y: names,
      x: space.map((p) => results.reduce((sum, r) => sum + difficulty(p, r.params[p.name]), 0) / results.length),
      marker: { symbol: "line-ns", size: 22, line: { width: 3, color: "#f59e0b" } },
      hovertemplate: "%{y}: mean %{x:.2f}<extra></extra>",
    });
  }
  const target = state.teacher.lesson_params ?? state.teacher.point ?? null;
  if (target) {
    const label = state.teacher.lesson_params ? "current lesson" : "fixed task";
    traces.push({
      meta: "difficulty-target", name: label, type: "scatter", mode: "markers",
      y: names, x: space.map((p) => difficulty(p, target[p.name])),
      marker: { symbol: "diamond", size: 11, color: "#dc2626", line: { width: 1, color: "#fff" } },
      hovertemplate: `%{y}: ${label} at %{x:.2f}<extra></extra>`,
    });
  }
  renderLesson(state);
  Plotly.react(
    "difficulty-plot",
    traces,
    baseLayout({
      margin: { l: 96, r: 16, t: 28, b: 44 },
      showlegend: true,
      legend: { orientation: "h", x: 1, xanchor: "right", y: 1.13, font: { color: MUTED } },
      xaxis: axis("difficulty (0 = easiest, 1 = hardest)", { range: [-0.03, 1.03], dtick: 0.1, showgrid: false }),
      yaxis: axis("", { autorange: "reversed", showgrid: false, type: "category" }),
      uirevision: "difficulty",
    }),
    PLOT_CONFIG,
  );
}

function renderLesson(state) {
  const box = document.getElementById("lesson");
  const teacher = state.teacher;
  box.hidden = teacher.lesson_params === undefined;
  if (box.hidden) return;
  const summary = document.createElement("p");
  summary.append(
    "Lesson ",
    Object.assign(document.createElement("strong"), { textContent: `${teacher.lesson + 1} of ${teacher.lessons}` }),
    ` · ${formatNumber(teacher.lesson_episodes)} episodes in this lesson · ${lessonRule(teacher)}`,
  );
  const params = document.createElement("dl");
  params.className = "params";
  for (const [name, value] of Object.entries(teacher.lesson_params)) {
    const item = document.createElement("div");
    item.append(
      Object.assign(document.createElement("dt"), { textContent: name }),
      Object.assign(document.createElement("dd"), { textContent: formatNumber(value) }),
    );
    params.append(item);
  }
  box.replaceChildren(summary, params);
}

/** What became of a fit, in words a reader needs no source code for, and the class that colours it. */
function fitOutcome(fit) {
  if (fit.error === null) return [fit.replayed ? "installed (redone at startup)" : "installed", ""];
  if (fit.error.startsWith("superseded by")) {
    return [`${fit.error}: the next fit fell due before this one could start, so this one was skipped`, "skipped"];
  }
  if (fit.error.startsWith("abandoned after")) {
    return [`${fit.error}: it ran past the time limit (KC_FIT_TIMEOUT_S), so its process was killed; the teacher kept its model`, "failed"];
  }
  return [`not installed: ${fit.error}; the teacher kept its model`, "failed"];
}

function renderFits(state) {
  showFitsStopped(state.curriculum.counters.fits_stopped);
  showWritesFailing(state.curriculum.counters.writes_failing);
  const fits = state.fits.slice(-FIT_ROWS).reverse();
  const notInstalled = state.fits.filter((fit) => fit.error !== null).length;
  const listed = fits.length < state.fits.length ? `, the newest ${fits.length} listed` : "";
  setText("fits-note", state.fits.length ? `last ${state.fits.length}${listed} · ${notInstalled} not installed` : "");
  document.getElementById("fit-rows").replaceChildren(
    ...fits.map((fit) => {
      const [outcome, className] = fitOutcome(fit);
      const row = document.createElement("tr");
      for (const [text, cellClass] of [
        [String(fit.index), "number"],
        [clock(fit.finished_at), ""],
        [className === "skipped" ? "–" : `${fit.duration_s.toFixed(2)} s`, "number"],
        [outcome, className],
      ]) {
        row.append(Object.assign(document.createElement("td"), { textContent: text, className: cellClass }));
      }
      return row;
    }),
  );
  document.getElementById("fits-empty").hidden = fits.length > 0;
}

/** "mean reward 4.2 (moves on above 5.5, back below 1)": the lesson plan's metric and its rule. */
function lessonRule(teacher) {
  const metric = teacher.metric === "success" ? "success rate" : "mean reward";
  const value = teacher.recent_metric ?? null;
  const { threshold, step_back_below: floor } = teacher.params;
  const rules = [];
  if (!teacher.final_lesson) rules.push(`moves on above ${formatNumber(threshold)}`);
  if (floor != null && teacher.lesson > 0) rules.push(`back below ${formatNumber(floor)}`);
  const shown = `${metric} ${value === null ? "–" : formatNumber(value)}`;
  return `${shown}${rules.length ? ` (${rules.join(", ")})` : ""}${teacher.final_lesson ? " · final lesson" : ""}`;
}

/* ---------- each teacher's own state, keyed on the state's entries (not on kind names) ---------- */

const REGION_SCALE = [[0, "#e0f2fe"], [0.5, "#38bdf8"], [1, "#075985"]];
const LEARNABILITY_SCALE = [[0, "#e5e7eb"], [0.5, "#f59e0b"], [1, "#9a3412"]];
const STATE_SHOWN_ELSEWHERE = new Set(["kind", "seed", "params", "tasks_sampled", "results_seen"]);
const MOVES_LISTED = 50;

function rectangle(low, high, xName, yName) {
  const [x0, x1, y0, y1] = [low[xName], high[xName], low[yName], high[yName]];
  return { x: [x0, x1, x1, x0, x0], y: [y0, y0, y1, y1, y0] };
}

/** Traces drawn under the tasks: `regions` coloured by progress, the `bounds` outline, the lesson `plan`. */
function stateBackdrop(teacher, xName, yName) {
  const traces = [];
  const regions = teacher.regions ?? [];
  const progressMax = Math.max(1e-9, ...regions.map((r) => Math.abs(r.progress)));
  regions.forEach((region, k) => {
    const colour = scaleColour(REGION_SCALE, Math.abs(region.progress) / progressMax);
    traces.push({
      meta: "region", name: `region ${k + 1}`, type: "scatter", mode: "lines", ...rectangle(region.low, region.high, xName, yName),
      fill: "toself", fillcolor: withAlpha(colour, 0.35), line: { color: withAlpha(colour, 0.9), width: 1 },
      hoveron: "fills", hoverinfo: "text",
      text: `region ${k + 1}<br>progress ${formatNumber(region.progress)}<br>${formatNumber(region.results)} results`,
    });
  });
  if (regions.length) {
    traces.push({
      meta: "region-centres", name: "region progress", type: "scatter", mode: "markers",
      x: regions.map((r) => (r.low[xName] + r.high[xName]) / 2), y: regions.map((r) => (r.low[yName] + r.high[yName]) / 2),
      customdata: regions.map((r) => [r.progress, r.results]),
      marker: {
        size: 4, color: regions.map((r) => Math.abs(r.progress)), cmin: 0, cmax: progressMax, colorscale: REGION_SCALE,
        colorbar: { title: { text: "|progress|", side: "right" }, x: 1.13, xpad: 8, thickness: 12, len: 0.9 },
      },
      hovertemplate: "progress %{customdata[0]:.3f}<br>%{customdata[1]} results<extra></extra>",
    });
  }
  if (teacher.bounds) {
    traces.push({
      meta: "bounds", name: "bounds", type: "scatter", mode: "lines", ...rectangle(teacher.bounds.low, teacher.bounds.high, xName, yName),
      line: { color: "#dc2626", width: 2, dash: "dash" }, hoverinfo: "skip",
    });
  }
  if (teacher.plan) {
    traces.push({
      meta: "plan", name: "lesson plan", type: "scatter", mode: "lines+markers",
      x: teacher.plan.map((lesson) => lesson[xName]), y: teacher.plan.map((lesson) => lesson[yName]),
      text: teacher.plan.map((_, k) => `lesson ${k + 1}`),
      line: { color: MUTED, width: 1, dash: "dot" }, marker: { size: 5, color: MUTED },
      hovertemplate: "%{text}<extra></extra>",
    });
  }
  return traces;
}

/** Traces drawn over the tasks: a candidate `pool` coloured by `pool_learnability`, `particles` and
 * the task the teacher hands out now (a lesson or a fixed point). */
function stateMarks(teacher, xName, yName) {
  const traces = [];
  const pool = teacher.pool ?? [];
  if (pool.length) {
    const scores = teacher.pool_learnability ?? pool.map(() => 0);
    const success = teacher.pool_success ?? pool.map(() => null);
    traces.push({
      meta: "pool", name: "candidate pool", type: "scatter", mode: "markers",
      x: pool.map((p) => p[xName]), y: pool.map((p) => p[yName]),
      customdata: pool.map((_, k) => [scores[k], success[k]]),
      marker: {
        size: 9, symbol: "square-open", line: { width: 2 }, color: scores, cmin: 0, cmax: 0.25,
        colorscale: LEARNABILITY_SCALE,
        colorbar: { title: { text: "p(1−p)", side: "right" }, x: 1.13, xpad: 8, thickness: 12, len: 0.9 },
      },
      hovertemplate: "candidate<br>p(1−p) %{customdata[0]:.3f}<br>p %{customdata[1]:.2f}<extra></extra>",
    });
  }
  const particles = teacher.particles ?? [];
  if (particles.length) {
    const values = teacher.particle_values ?? null;
    traces.push({
      meta: "particles", name: "particles", type: "scatter", mode: "markers",
      x: particles.map((p) => p[xName]), y: particles.map((p) => p[yName]),
      customdata: values ?? particles.map(() => null),
      marker: { size: 7, symbol: "circle-open", color: "#7c3aed", line: { width: 1.5 } },
      hovertemplate: values ? "particle<br>value %{customdata:.3f}<extra></extra>" : "particle<extra></extra>",
    });
  }
  const now = teacher.lesson_params ?? teacher.point ?? null;
  if (now) {
    const label = teacher.lesson_params ? `lesson ${teacher.lesson + 1}` : "fixed task";
    traces.push({
      meta: "current-task", name: label, type: "scatter", mode: "markers", x: [now[xName]], y: [now[yName]],
      marker: { symbol: "diamond", size: 14, color: "#dc2626", line: { width: 1.5, color: "#fff" } },
      hovertemplate: `${label}<extra></extra>`,
    });
  }
  return traces;
}

/** The teacher card: its scalar state entries, the history of its `moves`, and a level kind's likeliest levels. */
function renderTeacherState(state) {
  const teacher = state.teacher;
  const scalars = Object.entries(teacher).filter(
    ([name, value]) => !STATE_SHOWN_ELSEWHERE.has(name) && (value === null || typeof value !== "object"),
  );
  const moves = teacher.moves ?? null;
  const levels = Array.isArray(teacher.levels) ? teacher.levels : null;
  const card = document.getElementById("teacher-card");
  card.hidden = !scalars.length && moves === null && levels === null;
  if (card.hidden) return;
  document.getElementById("teacher-state").replaceChildren(
    ...scalars.map(([name, value]) => {
      const item = document.createElement("div");
      item.append(
        Object.assign(document.createElement("dt"), { textContent: name }),
        Object.assign(document.createElement("dd"), { textContent: formatValue(value) }),
      );
      return item;
    }),
  );
  document.getElementById("moves-box").hidden = moves === null;
  if (moves !== null) renderMoves(moves, teacher.moves_total ?? moves.length);
  document.getElementById("levels-box").hidden = levels === null;
  if (levels !== null) renderLevels(levels, teacher.level_count ?? levels.length, state);
}

/** A level kind's `levels`: the likeliest next draws, most likely first, each numbered on the axis, with its own
 *  columns (a score, a success rate) and its recent results on hover. */
function renderLevels(levels, total, state) {
  setText("levels-note", `the ${formatNumber(levels.length)} likeliest next of ${formatNumber(total)}`);
  const shownApart = new Set(["level", "task", "probability"]);
  const space = state.curriculum.config.space;
  const tally = resultsPerTask(space, state.recent_results);
  Plotly.react(
    document.getElementById("levels-plot"),
    [{
      meta: "levels", name: "levels", type: "bar", marker: { color: "#2563eb" },
      x: levels.map((row) => `#${row.level}`), y: levels.map((row) => row.probability),
      text: levels.map((row) => [
        ...Object.entries(row).filter(([name]) => !shownApart.has(name)).map(([name, value]) => `${name} ${formatValue(value)}`),
        tallyText(tally.get(taskKey(space, row.task))),
      ].join("<br>")),
      textposition: "none",
      hovertemplate: "level %{x}: chance %{y:.3f}<br>%{text}<extra></extra>",
    }],
    baseLayout({
      margin: { l: 52, r: 16, t: 8, b: 52 },
      xaxis: axis("level", { type: "category", tickangle: -90, tickfont: { size: 9 } }),
      yaxis: axis("chance of the next draw", { rangemode: "tozero" }),
      uirevision: "levels",
    }),
    PLOT_CONFIG,
  );
}

function renderMoves(moves, total) {
  setText(
    "moves-note",
    moves.length < total ? `newest ${formatNumber(moves.length)} of ${formatNumber(total)}` : `${formatNumber(total)} in all`,
  );
  document.getElementById("moves-empty").hidden = moves.length > 0;
  const plot = document.getElementById("moves-plot");
  const numeric = moves.length > 0 && moves.every((m) => typeof m.from === "number" && typeof m.to === "number");
  plot.hidden = !numeric;
  if (numeric) {
    Plotly.react(
      plot,
      [{
        meta: "moves", name: "moves", type: "scatter", mode: "lines+markers", line: { shape: "hv", color: "#2563eb" },
        x: [0, ...moves.map((m) => m.at_results)], y: [moves[0].from, ...moves.map((m) => m.to)],
        text: ["", ...moves.map((m) => m.why)], hovertemplate: "after %{x} results: %{y}<br>%{text}<extra></extra>",
      }],
      baseLayout({
        margin: { l: 52, r: 16, t: 8, b: 40 },
        xaxis: axis("results"),
        yaxis: axis("moved to", { rangemode: "tozero" }),
        uirevision: "moves",
      }),
      PLOT_CONFIG,
    );
  }
  const newestFirst = moves.slice(-MOVES_LISTED).reverse();
  document.getElementById("moves-rows").replaceChildren(
    ...newestFirst.map((move) => {
      const row = document.createElement("tr");
      for (const [text, className] of [
        [formatNumber(move.at_results), "number"], [formatValue(move.from), ""], [formatValue(move.to), ""], [move.why, ""],
      ]) {
        row.append(Object.assign(document.createElement("td"), { textContent: text, className }));
      }
      return row;
    }),
  );
}

/* ---------- start ---------- */

if (document.body.dataset.page === "curricula") {
  poll(`${api}/curricula`, renderCurricula, unreachable);
} else {
  const name = document.body.dataset.curriculum;
  for (const id of ["dim-x", "dim-y"]) {
    document.getElementById(id).addEventListener("change", () => view.state && renderTaskSpace());
  }
  poll(
    `${api}/curricula/${encodeURIComponent(name)}/state`,
    renderCurriculum,
    (error) => (error instanceof HttpError && error.status === 404 ? `no curriculum named ${name} yet — waiting for it` : unreachable(error)),
  );
}
