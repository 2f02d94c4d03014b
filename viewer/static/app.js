// hcgym view: one page, hash-routed (#/runs, #/episodes?..., #/episode?..., #/evals).
// Every piece of run data is inserted as text (textContent), never as HTML: episodes hold model output.
"use strict";

const COLORS = ["#2356a8", "#c0392b", "#1e8449", "#8e44ad", "#d68910", "#138d90", "#7f8c8d", "#a04000"];

// The paper's training-dynamics figure, then the system panels. A panel plots every listed key
// present in a run; `prefix` plots every key that starts with it.
const PANELS = [
  { title: "Accuracy", keys: ["accuracy"], val: ["val_accuracy"] },
  { title: "KL to teacher", keys: ["kl_teacher"] },
  { title: "KL to reference", keys: ["kl_ref"] },
  { title: "Response length (tokens)", keys: ["response_length_mean"], val: ["val_response_length_mean"] },
  { title: "Turns per episode", keys: ["turns_mean"], val: ["val_turns_mean"] },
  { title: "Reward", keys: ["reward_mean"], val: ["val_reward_mean"] },
  { title: "Reward components", prefix: "reward_component/" },
  { title: "Filtered fraction (dynamic sampling)", keys: ["filtered_groups_frac"] },
  { title: "Policy lag (versions)", keys: ["policy_lag_mean", "policy_lag_max"] },
  { title: "Padding share of forward tokens", keys: ["learner_padding_frac", "teacher_padding_frac"] },
  { title: "Step time (s)", keys: ["time_step_s", "time_generation_s", "time_learner_s", "time_env_s",
                                   "time_weight_sync_s", "time_batch_wait_s"] },
];

const state = { sources: [], metrics: {}, selectedRuns: null, logScale: false, smoothing: 0 };

function el(tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k === "class") node.className = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else node.setAttribute(k, v === true ? "" : v);
  }
  for (const child of children.flat()) {
    if (child === null || child === undefined || child === false) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

function svgEl(tag, attrs) {
  const node = document.createElementNS("http://www.w3.org/2000/svg", tag);
  for (const [k, v] of Object.entries(attrs || {})) node.setAttribute(k, v);
  return node;
}

async function api(path, params) {
  const query = new URLSearchParams();
  for (const [k, v] of Object.entries(params || {})) if (v !== undefined && v !== null && v !== "") query.set(k, v);
  const response = await fetch(`/api/${path}?${query}`);
  const body = await response.json();
  if (!response.ok) throw new Error(body.error || `HTTP ${response.status}`);
  return body;
}

function fmt(value, digits = 3) {
  if (value === null || value === undefined) return "–";
  if (typeof value === "number") return Number.isInteger(value) ? String(value) : value.toFixed(digits);
  return String(value);
}

function fixed(value, digits = 3) {
  // Report numbers always with the same digits (a CI of [1, 1] reads as [1.000, 1.000]).
  return value === null || value === undefined ? "–" : Number(value).toFixed(digits);
}

function route() {
  const hash = location.hash.slice(1) || "/runs";
  const [path, query] = hash.split("?");
  return { path, params: Object.fromEntries(new URLSearchParams(query || "")) };
}

function go(path, params) {
  const query = new URLSearchParams();
  for (const [k, v] of Object.entries(params || {})) if (v !== undefined && v !== null && v !== "") query.set(k, v);
  location.hash = `${path}${[...query].length ? "?" + query : ""}`;
}

function runs() { return state.sources.filter((s) => s.kind === "run"); }
function evals() { return state.sources.filter((s) => s.kind === "eval"); }
function sourceName(id) { const s = state.sources.find((x) => x.id === id); return s ? s.label : id; }

// ---- charts -----------------------------------------------------------------------------------
function smooth(values, weight) {
  // Exponential moving average, debiased (as TensorBoard): a spike no longer flattens the curve's start.
  if (!weight) return values;
  let last = 0, n = 0;
  return values.map((v) => { last = last * weight + (1 - weight) * v; n += 1; return last / (1 - weight ** n); });
}

function chart(series, { logScale, onPick }) {
  // series: [{label, color, points: [[x, y], ...]}]
  const W = 420, H = 220, L = 48, R = 10, T = 8, B = 22;
  const svg = svgEl("svg", { class: "chart", viewBox: `0 0 ${W} ${H}`, preserveAspectRatio: "none" });
  const all = series.flatMap((s) => s.points).filter(([, y]) => Number.isFinite(y) && (!logScale || y > 0));
  const tip = el("div", { class: "tip" }, all.length ? "hover for values · click for that step's episodes" : "no data");
  if (!all.length) return el("div", {}, svg, tip);
  const xs = all.map(([x]) => x), ys = all.map(([, y]) => (logScale ? Math.log10(y) : y));
  let [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  if (x0 === x1) { x0 -= 1; x1 += 1; }
  if (y0 === y1) { y0 -= 1; y1 += 1; }
  const sx = (x) => L + ((x - x0) / (x1 - x0)) * (W - L - R);
  const sy = (y) => T + (1 - ((logScale ? Math.log10(y) : y) - y0) / (y1 - y0)) * (H - T - B);
  svg.append(svgEl("line", { class: "axis", x1: L, y1: H - B, x2: W - R, y2: H - B }));
  svg.append(svgEl("line", { class: "axis", x1: L, y1: T, x2: L, y2: H - B }));
  for (const frac of [0, 0.5, 1]) {
    const v = y0 + frac * (y1 - y0);
    const label = svgEl("text", { x: 2, y: T + (1 - frac) * (H - T - B) + 3 });
    label.textContent = logScale ? `1e${v.toFixed(1)}` : fmt(v, 3);
    svg.append(label);
  }
  for (const x of [x0, x1]) {
    const label = svgEl("text", { x: sx(x) - 4, y: H - 6 });
    label.textContent = fmt(x, 0);
    svg.append(label);
  }
  for (const s of series) {
    const pts = s.points.filter(([, y]) => Number.isFinite(y) && (!logScale || y > 0));
    if (!pts.length) continue;
    svg.append(svgEl("polyline", { fill: "none", stroke: s.color, "stroke-width": 1.6, "data-label": s.label,
      points: pts.map(([x, y]) => `${sx(x).toFixed(1)},${sy(y).toFixed(1)}`).join(" ") }));
  }
  const cursor = svgEl("line", { class: "cursor", y1: T, y2: H - B, x1: -10, x2: -10 });
  svg.append(cursor);
  const steps = [...new Set(xs)].sort((a, b) => a - b);
  const nearest = (event) => {
    const box = svg.getBoundingClientRect();
    const x = x0 + ((event.clientX - box.left) / box.width * W - L) / (W - L - R) * (x1 - x0);
    return steps.reduce((best, s) => (Math.abs(s - x) < Math.abs(best - x) ? s : best), steps[0]);
  };
  svg.addEventListener("mousemove", (event) => {
    const step = nearest(event);
    cursor.setAttribute("x1", sx(step)); cursor.setAttribute("x2", sx(step));
    tip.textContent = `step ${step}: ` + series.map((s) => {
      const p = s.points.find(([x]) => x === step);
      return `${s.label} ${p ? fmt(p[1], 4) : "–"}`;
    }).join(" · ");
  });
  if (onPick) svg.addEventListener("click", (event) => onPick(nearest(event)));
  const legend = el("div", { class: "legend" },
    series.map((s) => el("span", {}, el("i", { style: `background:${s.color}` }), s.label)));
  return el("div", {}, svg, legend, tip);
}

// ---- pages ------------------------------------------------------------------------------------
async function runsPage(root) {
  const available = runs();
  if (!available.length) { root.append(el("p", { class: "muted" }, "No training run is being served.")); return; }
  if (!state.selectedRuns) state.selectedRuns = new Set(available.map((r) => r.id));
  for (const run of available) if (!state.metrics[run.id]) state.metrics[run.id] = await api("run/metrics", { source: run.id });
  const toolbar = el("div", { class: "toolbar" },
    available.map((run) => el("label", {}, el("input", { type: "checkbox", "data-run": run.id,
      checked: state.selectedRuns.has(run.id), onchange: (e) => {
        e.target.checked ? state.selectedRuns.add(run.id) : state.selectedRuns.delete(run.id); render(); } }),
      ` ${run.label}`)),
    el("label", {}, el("input", { type: "checkbox", id: "log-scale", checked: state.logScale,
      onchange: (e) => { state.logScale = e.target.checked; render(); } }), " log scale"),
    el("label", {}, "smoothing ", el("input", { type: "range", id: "smoothing", min: 0, max: 0.95, step: 0.05,
      value: state.smoothing, onchange: (e) => { state.smoothing = Number(e.target.value); render(); } }),
      ` ${state.smoothing.toFixed(2)}`));
  root.append(toolbar);
  const grid = el("div", { class: "grid" });
  const chosen = available.filter((r) => state.selectedRuns.has(r.id));
  for (const panel of PANELS) {
    const series = [];
    chosen.forEach((run, runIndex) => {
      const { train, validation } = state.metrics[run.id];
      const keysIn = (rows, keys, prefix) => {
        const present = new Set(rows.flatMap((r) => Object.keys(r)));
        return prefix ? [...present].filter((k) => k.startsWith(prefix)).sort() : (keys || []).filter((k) => present.has(k));
      };
      const add = (rows, key, dashed) => {
        const pts = rows.filter((r) => typeof r[key] === "number").map((r) => [r.step, r[key]]);
        const ys = smooth(pts.map(([, y]) => y), state.smoothing);
        series.push({ label: (chosen.length > 1 ? `${run.label}: ` : "") + key,
          color: COLORS[(series.length + runIndex) % COLORS.length], points: pts.map(([x], i) => [x, ys[i]]), dashed });
      };
      keysIn(train, panel.keys, panel.prefix).forEach((k) => add(train, k, false));
      keysIn(validation, panel.val, null).forEach((k) => add(validation, k, true));
    });
    if (!series.length) continue;
    const onPick = chosen.length ? (step) => go("/episodes", { source: chosen[0].id, part: "train", step }) : null;
    grid.append(el("div", { class: "panel", "data-panel": panel.title }, el("h3", {}, panel.title),
      chart(series, { logScale: state.logScale, onPick })));
  }
  root.append(grid);
  for (const run of chosen) {
    const config = await api("run/config", { source: run.id });
    root.append(el("details", { class: "panel" }, el("summary", {}, `config.yaml · ${run.label}`), el("pre", {}, config.text)));
  }
}

const FILTERS = [
  ["part", "part"], ["benchmark", "benchmark"], ["domain", "domain"], ["step", "step"], ["end_reason", "end reason"],
  ["error_kind", "error kind", "error_kinds"], ["min_severity", "safety ≥", "safety_max_severity"],
];

async function episodesPage(root, params) {
  const sources = state.sources;
  if (!sources.length) { root.append(el("p", { class: "muted" }, "Nothing is being served.")); return; }
  const source = params.source || sources[0].id;
  const query = { ...params, source, limit: params.limit || 50, offset: params.offset || 0 };
  const page = await api("episodes", query);
  const update = (changes) => go("/episodes", { ...query, offset: 0, ...changes });
  const form = el("div", { class: "toolbar", id: "filters" },
    el("label", {}, "source ", el("select", { id: "f-source", onchange: (e) => go("/episodes", { source: e.target.value }) },
      sources.map((s) => el("option", { value: s.id, selected: s.id === source }, `${s.label} (${s.kind})`)))),
    FILTERS.map(([name, label, facetName]) => {
      const values = page.facets[facetName || name];
      if (!values) return null;
      return el("label", {}, `${label} `, el("select", { id: `f-${name}`, onchange: (e) => update({ [name]: e.target.value }) },
        el("option", { value: "" }, "any"), values.map((v) => el("option", { value: v, selected: String(v) === params[name] }, v))));
    }),
    el("label", {}, "correct ", el("select", { id: "f-correct", onchange: (e) => update({ correct: e.target.value }) },
      ["", "true", "false"].map((v) => el("option", { value: v, selected: v === (params.correct || "") }, v || "any")))),
    el("label", {}, "task ", el("input", { id: "f-task", value: params.task || "", size: 14,
      onchange: (e) => update({ task: e.target.value }) })),
    el("label", {}, "reward ", el("input", { id: "f-reward_min", type: "number", step: "0.05", value: params.reward_min || "",
      onchange: (e) => update({ reward_min: e.target.value }) }), " – ",
      el("input", { id: "f-reward_max", type: "number", step: "0.05", value: params.reward_max || "",
        onchange: (e) => update({ reward_max: e.target.value }) })));
  root.append(form);
  const first = page.matched ? page.offset + 1 : 0;
  root.append(el("p", { id: "episode-count" }, `${page.matched} of ${page.total} episodes match · showing ${first}–${page.offset + page.rows.length}`));
  const isEval = state.sources.find((s) => s.id === source)?.kind === "eval";
  const columns = isEval
    ? ["benchmark", "task_id", "condition", "seed", "correct", "reward", "end_reason", "turns", "tool_calls", "safety_max_severity", "error_kinds"]
    : ["part", "step", "domain", "task_id", "reward", "correct", "end_reason", "num_tool_calls", "response_tokens", "safety_max_severity", "error_kinds", "teacher_hint"];
  const table = el("table", { id: "episodes" }, el("tr", {}, columns.map((c) => el("th", {}, c.replaceAll("_", " ")))));
  for (const row of page.rows) {
    const target = isEval ? { source, row_id: row.row_id } : { source, file: row.file, row: row.row };
    table.append(el("tr", { class: "clickable", "data-task": row.task_id, onclick: () => go("/episode", target) },
      columns.map((c) => el("td", { class: typeof row[c] === "number" ? "num" : "" },
        Array.isArray(row[c]) ? row[c].join(", ") : fmt(row[c])))));
  }
  root.append(table);
  const pager = el("div", { class: "toolbar" },
    el("button", { id: "prev", disabled: page.offset === 0, onclick: () => go("/episodes", { ...query, offset: Math.max(0, page.offset - query.limit) }) }, "← previous"),
    el("button", { id: "next", disabled: page.offset + page.rows.length >= page.matched,
      onclick: () => go("/episodes", { ...query, offset: page.offset + Number(query.limit) }) }, "next →"));
  root.append(pager);
}

function rewardBlock(components, details) {
  const box = el("div", { class: "panel", id: "reward" }, el("h3", {}, "Reward (5D)"));
  const kv = el("div", { class: "kv" });
  for (const [k, v] of Object.entries(components || {})) kv.append(el("span", {}, k), el("span", { "data-component": k }, fmt(v)));
  box.append(kv);
  const reasons = (details || {}).dimensions || (details || {}).reasons;
  if (details && Object.keys(details).length) {
    box.append(el("details", {}, el("summary", {}, "why (the graders' details)"), el("pre", {}, JSON.stringify(details, null, 2))));
  }
  const violations = (details || {}).violations || [];
  if (violations.length) {
    const table = el("table", { id: "violations" }, el("tr", {}, ["pattern", "severity", "category", "evidence"].map((h) => el("th", {}, h))));
    for (const v of violations) {
      table.append(el("tr", {}, el("td", {}, v.pattern_id || v.pattern || v.id || "–"),
        el("td", {}, el("span", { class: "badge bad" }, fmt(v.severity))), el("td", {}, v.category || "–"),
        el("td", {}, v.evidence || v.message || "")));
    }
    box.append(el("h3", {}, "Safety violations"), table);
  } else {
    box.append(el("p", { class: "muted" }, "No safety violation."));
  }
  return box;
}

function turnBlock(turn, kl) {
  const box = el("div", { class: "turn", "data-turn": turn.index });
  box.append(el("h4", {}, `Turn ${turn.index + 1}`, el("span", { class: "badge" }, turn.action_format),
    kl === null || kl === undefined ? null : el("span", { class: "badge", "data-kl": kl }, `distillation KL ${fmt(kl, 4)}`)));
  if (turn.message) box.append(el("div", { class: "muted" }, "message"), el("pre", {}, turn.message));
  for (const call of turn.tool_calls || []) {
    box.append(el("div", { class: `call${call.error ? " failed" : ""}`, "data-tool": call.name },
      el("strong", {}, call.name), call.submit ? el("span", { class: "badge good" }, "submit") : null,
      call.error_kind ? el("span", { class: "badge bad" }, call.error_kind) : null,
      el("pre", { class: "args" }, JSON.stringify(call.arguments, null, 2)),
      call.error ? el("pre", { class: "error" }, call.error) : el("pre", { class: "result" }, call.result ?? "")));
  }
  for (const err of turn.parse_errors || []) box.append(el("div", { class: "error", "data-parse-error": "" }, `parse error: ${err}`));
  if (turn.observation) box.append(el("details", {}, el("summary", {}, "observation sent back"), el("pre", {}, turn.observation)));
  box.append(el("details", {}, el("summary", {}, "raw action"), el("pre", {}, turn.action)));
  return box;
}

async function episodePage(root, params) {
  const source = state.sources.find((s) => s.id === params.source);
  if (!source) throw new Error(`unknown source ${params.source}`);
  root.append(el("p", {}, el("a", { href: "#/episodes?source=" + source.id }, "← episodes")));
  if (source.kind === "eval") {
    const data = await api("eval/episode", params);
    const r = data.result;
    root.append(el("h2", {}, `${r.benchmark} · ${r.task_id}`, " ", el("span", { class: `badge ${r.correct ? "good" : "bad"}` }, r.correct ? "correct" : "incorrect")));
    root.append(el("div", { class: "panel kv", id: "answer" }, el("span", {}, "answer"), el("span", { id: "submitted" }, fmt(r.answer)),
      el("span", {}, "gold"), el("span", { id: "gold" }, fmt(r.gold)), el("span", {}, "end reason"), el("span", {}, r.end_reason),
      el("span", {}, "condition"), el("span", {}, r.condition)));
    root.append(rewardBlock(r.reward_components, { violations: Object.entries(r.safety_violations || {}).map(([severity, n]) => ({ severity: Number(severity), pattern: `${n} violation(s)` })) }));
    for (const [i, m] of (data.messages || []).entries()) {
      root.append(el("div", { class: "turn", "data-message": i }, el("h4", {}, m.role || "message"),
        el("pre", {}, typeof m.content === "string" ? m.content : JSON.stringify(m.content, null, 2)),
        m.tool_calls ? el("pre", { class: "args" }, JSON.stringify(m.tool_calls, null, 2)) : null));
    }
    return;
  }
  const s = await api("run/episode", params);
  const ep = s.episode || {};
  root.append(el("h2", {}, `${s.domain} · ${s.task_id}`, " ", el("span", { class: `badge ${s.correct ? "good" : "bad"}` }, s.correct ? "correct" : "incorrect"),
    el("span", { class: "badge" }, `step ${s.step} (${s.part})`), el("span", { class: "badge" }, `reward ${fmt(s.reward)}`)));
  if (ep.first_observation) {
    // The first observation is the domain policy, the tool list, then "# Task" and the ticket.
    const at = ep.first_observation.lastIndexOf("# Task");
    const ticket = at >= 0 ? ep.first_observation.slice(at + "# Task".length).trim() : ep.first_observation;
    root.append(el("div", { class: "panel", id: "ticket" }, el("h3", {}, "Ticket"), el("pre", {}, ticket),
      at >= 0 ? el("details", {}, el("summary", {}, "policy and tools the agent was shown"), el("pre", {}, ep.first_observation.slice(0, at))) : null));
  }
  const gold = s.gold;
  root.append(el("div", { class: "panel kv", id: "answer" }, el("span", {}, "submitted answer"), el("span", { id: "submitted" }, fmt(ep.submitted_answer)),
    el("span", {}, "gold"), el("span", { id: "gold" }, fmt(gold)), el("span", {}, "end reason"), el("span", {}, s.end_reason || (s.metadata || {}).end_reason || (s.metadata || {}).truncation || "–"),
    el("span", {}, "sample"), el("span", {}, s.sample_id)));
  if (s.teacher_hint && s.teacher_hint !== "none") {
    root.append(el("div", { class: "panel", id: "hint" }, el("h3", {}, `Teacher hint (${s.teacher_hint})`), el("pre", {}, s.hint_text || s.teacher_hint)));
  }
  root.append(rewardBlock(s.reward_components, ep.reward_details));
  if (!s.episode) root.append(el("p", { class: "muted" }, "This trajectory file predates episode records: only scores are shown."));
  (ep.turns || []).forEach((turn, i) => root.append(turnBlock(turn, (s.turn_kl || [])[i])));
}

async function evalsPage(root, params) {
  const available = evals();
  if (!available.length) { root.append(el("p", { class: "muted" }, "No evaluation folder is being served.")); return; }
  for (const source of available) {
    const summary = await api("eval/summary", { source: source.id });
    const panel = el("div", { class: "panel", "data-eval": source.id }, el("h3", {}, `${summary.label} · ${summary.episodes} episodes`));
    const table = el("table", { class: "benchmarks" }, el("tr", {}, ["benchmark", "metric", "value [95% CI]", "n", "other metrics"].map((h) => el("th", {}, h))));
    for (const b of summary.benchmarks) {
      const primary = b.metrics.find((m) => m.metric === b.primary) || b.metrics[0];
      const ci = (m) => `${fixed(m.estimate)} [${fixed(m.low)}, ${fixed(m.high)}]`;
      table.append(el("tr", { "data-benchmark": b.benchmark },
        el("td", {}, el("a", { href: `#/episodes?source=${source.id}&benchmark=${encodeURIComponent(b.benchmark)}` }, b.title)),
        el("td", {}, b.primary),
        el("td", { class: "num", "data-value": primary.estimate },
          el("a", { href: `#/episodes?source=${source.id}&benchmark=${encodeURIComponent(b.benchmark)}`, title: "the episodes behind this number" }, ci(primary))),
        el("td", { class: "num" }, primary.n),
        el("td", {}, b.metrics.filter((m) => m !== primary).map((m) => `${m.metric} ${ci(m)}`).join("; "))));
    }
    panel.append(table);
    root.append(panel);
  }
  if (available.length >= 2) {
    const a = params.a || available[0].id, b = params.b || available[1].id;
    const pick = (name, value) => el("select", { id: `cmp-${name}`, onchange: (e) => go("/evals", { ...params, a, b, [name]: e.target.value }) },
      available.map((s) => el("option", { value: s.id, selected: s.id === value }, s.label)));
    const panel = el("div", { class: "panel", id: "compare" }, el("h3", {}, "Compare two evaluations (paired bootstrap, McNemar)"),
      el("div", { class: "toolbar" }, "A ", pick("a", a), " B ", pick("b", b)));
    root.append(panel);
    const cmp = await api("eval/compare", { a, b });
    const table = el("table", {}, el("tr", {}, ["benchmark", "metric", "items", "A", "B", "B − A [95% CI]", "McNemar p"].map((h) => el("th", {}, h))));
    for (const e of cmp.benchmarks) {
      const d = e.difference;
      table.append(el("tr", { "data-benchmark": e.benchmark },
        el("td", {}, el("a", { href: `#/episodes?source=${a}&benchmark=${encodeURIComponent(e.benchmark)}` }, e.benchmark)),
        el("td", {}, e.metric), el("td", { class: "num" }, e.items),
        el("td", { class: "num" }, fixed(e.a)), el("td", { class: "num" }, fixed(e.b)),
        el("td", { class: "num" }, `${fixed(d.estimate)} [${fixed(d.low)}, ${fixed(d.high)}]`), el("td", { class: "num" }, e.mcnemar ? fmt(e.mcnemar.p_value, 4) : "–")));
    }
    panel.append(table);
    if (cmp.unshared.length) panel.append(el("p", { class: "muted" }, `No shared items: ${cmp.unshared.join(", ")}`));
  }
}

async function render() {
  const root = document.getElementById("app");
  const { path, params } = route();
  for (const id of ["runs", "episodes", "evals"]) document.getElementById(`nav-${id}`).classList.toggle("active", path === `/${id}`);
  const fresh = el("main", { id: "app" });
  try {
    if (path === "/episodes") await episodesPage(fresh, params);
    else if (path === "/episode") await episodePage(fresh, params);
    else if (path === "/evals") await evalsPage(fresh, params);
    else await runsPage(fresh, params);
  } catch (error) {
    fresh.append(el("p", { class: "error", id: "page-error" }, String(error.message || error)));
  }
  root.replaceWith(fresh);
  // For tests and scripts: which page is shown, and a counter that changes on every render.
  document.body.dataset.ready = path;
  document.body.dataset.renders = String(Number(document.body.dataset.renders || 0) + 1);
}

(async function start() {
  try {
    state.sources = await api("sources");
    document.getElementById("status").textContent = `${runs().length} run(s), ${evals().length} evaluation(s)`;
  } catch (error) {
    document.getElementById("app").replaceChildren(el("p", { class: "error" }, String(error.message || error)));
    return;
  }
  window.addEventListener("hashchange", render);
  render();
})();
