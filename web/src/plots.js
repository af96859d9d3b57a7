// Plots of finished jobs' results with Chart.js (globalThis.Chart, from vendor/). Every plot is
// a scatter chart whose datasets are polylines (showLine) or markers, so that branches that
// fold back in their parameter and curves in a parameter plane draw as they are.
//
// The plot's container gets data-kind, data-series (datasets with points) and data-points
// (points drawn): what a test or a user's script can check without reading the canvas.

const COLORS = {
  stable: '#1f5f99',
  unstable: '#d1495b',
  period2: '#2a9d8f',
  FOLD: '#1f5f99',
  PERIOD_DOUBLING: '#d1495b',
  GRAZING: '#2a9d8f',
  NEIMARK_SACKER: '#8e44ad',
  special: '#111111',
  optimum: '#e09f3e',
};

// Short labels of special points (continue.proto SpecialPoint.Kind) and codimension-2 points.
const SPECIAL_LABELS = {
  FOLD: 'F', PERIOD_DOUBLING: 'PD', NEIMARK_SACKER: 'NS', BRANCH_POINT: 'BP', GRAZING_L1: 'Gl1',
  GRAZING_L2: 'Gl2', GRAZING_PI: 'GPi', SIGNATURE_CHANGE: 'SC', ROP_MAX: 'ROPmax',
  POWER_MAX: 'Pmax', FOLD_GRAZING: 'FG', FLIP_GRAZING: 'FlG', FOLD_FLIP: 'FF', NS_GRAZING: 'NSG',
  DOUBLE_GRAZING: 'DG', CUSP: 'C', RESONANCE_1_1: 'R1', RESONANCE_1_2: 'R2', RESONANCE_1_3: 'R3',
  RESONANCE_1_4: 'R4',
};

const PARAM_NAMES = ['a', 'b', 'omega', 'xi', 'g', 'phi0'];

let chart = null;

// Draws each point's `label` (set on the point objects of datasets with `labelled`) beside it.
// Points within a few pixels of each other (a period doubling at a grazing) share one label,
// their labels joined by "/", instead of overprinting.
const pointLabels = {
  id: 'pointLabels',
  afterDatasetsDraw(c) {
    const spots = new Map();  // pixel cell -> {x, y, labels}
    c.data.datasets.forEach((dataset, i) => {
      if (!dataset.labelled || !c.isDatasetVisible(i)) return;
      c.getDatasetMeta(i).data.forEach((element, j) => {
        const label = dataset.data[j].label;
        if (!label) return;
        const key = `${Math.round(element.x / 4)},${Math.round(element.y / 4)}`;
        const spot = spots.get(key) ?? {x: element.x, y: element.y, labels: new Set()};
        spot.labels.add(label);
        spots.set(key, spot);
      });
    });
    const {ctx} = c;
    ctx.save();
    ctx.font = '11px system-ui, sans-serif';
    ctx.fillStyle = '#111';
    for (const {x, y, labels} of spots.values()) ctx.fillText([...labels].join('/'), x + 5, y - 5);
    ctx.restore();
  },
};

function line(label, points, color, {dashed = false, legend = true} = {}) {
  return {label, data: points, showLine: true, borderColor: color, backgroundColor: color,
    borderWidth: 1.5, borderDash: dashed ? [6, 4] : [], pointRadius: 0, legend};
}

function markers(label, points, color, {style = 'circle', radius = 4, labelled = true} = {}) {
  return {label, data: points, showLine: false, borderColor: color, backgroundColor: color,
    pointStyle: style, pointRadius: radius, labelled, legend: true};
}

/**
 * Draws `datasets` in `container` (its canvas) with axis titles, replacing the last plot. With
 * `y2Title`, a second y axis on the right for the datasets whose yAxisID is 'y2'.
 */
function draw(container, kind, datasets, xTitle, yTitle, {y2Title} = {}) {
  const canvas = container.querySelector('canvas');
  if (chart) chart.destroy();
  const drawn = datasets.filter((d) => d.data.length > 0);
  chart = new globalThis.Chart(canvas, {
    type: 'scatter',
    data: {datasets: drawn},
    options: {
      animation: false,
      responsive: true,
      maintainAspectRatio: false,
      scales: {
        x: {type: 'linear', title: {display: true, text: xTitle}},
        y: {type: 'linear', title: {display: true, text: yTitle}},
        ...(y2Title ? {y2: {type: 'linear', position: 'right', grid: {drawOnChartArea: false},
          title: {display: true, text: y2Title}}} : {}),
      },
      plugins: {
        legend: {
          // Thin boxes: a line's entry shows its colour and dash, not a hatched block.
          labels: {boxHeight: 4, filter: (item, data) => data.datasets[item.datasetIndex].legend},
        },
        tooltip: {
          callbacks: {
            label: (item) => `${item.dataset.label}: (${item.parsed.x.toPrecision(6)}, ` +
              `${item.parsed.y.toPrecision(6)})${item.raw.label ? ` ${item.raw.label}` : ''}`,
          },
        },
      },
    },
    plugins: [pointLabels],
  });
  container.dataset.kind = kind;
  container.dataset.series = String(drawn.length);
  // Points with a value (a null y is a gap in its line).
  container.dataset.points = String(drawn.reduce((n, d) => n + d.data.filter(
      (point) => point.y !== null).length, 0));
}

// Splits a branch's points into runs of equal stability (each run shares its end point with the
// next, so that the polyline has no gap).
function stabilityRuns(points, x, y) {
  const runs = [];
  for (const point of points) {
    const stable = Boolean(point.stable);
    const xy = {x: x(point), y: y(point)};
    const last = runs.at(-1);
    if (last && last.stable === stable) {
      last.points.push(xy);
    } else {
      if (last) last.points.push(xy);
      runs.push({stable, points: [xy]});
    }
  }
  return runs;
}

/** The measures a continuation can be plotted against (BranchPoint / SpecialPoint fields). */
export const CONTINUE_MEASURES = {
  rop: 'rate of progression (ROP)',
  power: 'dissipated power',
  p: 'bit position p at the section s = 0',
};

/** The one-parameter diagram of a ContinueResult: parameter against `measure`. */
export function plotContinue(container, result, request, measure = 'rop') {
  const datasets = [];
  const y = (point) => point[measure] ?? 0;
  const addBranch = (branch, name, stableColor, unstableColor) => {
    let seenStable = false;
    let seenUnstable = false;
    for (const run of stabilityRuns(branch.points ?? [], (p) => p.value, y)) {
      const first = run.stable ? !seenStable : !seenUnstable;
      if (run.stable) seenStable = true;
      else seenUnstable = true;
      datasets.push(line(`${name}, ${run.stable ? 'stable' : 'unstable'}`, run.points,
          run.stable ? stableColor : unstableColor, {dashed: !run.stable, legend: first}));
    }
    const specials = (branch.specialPoints ?? []).map((s) => ({
      x: s.value, y: s[measure] ?? 0, label: SPECIAL_LABELS[s.kind] ?? s.kind}));
    datasets.push(markers(`${name}: special points`, specials, COLORS.special,
        {style: 'rectRot', radius: 5}));
  };
  addBranch(result, 'branch', COLORS.stable, COLORS.unstable);
  if (result.periodDoubledBranch) {
    addBranch(result.periodDoubledBranch, 'period-2 branch', COLORS.period2, '#e76f51');
  }
  draw(container, 'continue', datasets, request?.param ?? 'parameter', CONTINUE_MEASURES[measure]);
}

/** The two parameters a trace's points vary in: the request's, or those whose values change. */
function planeOf(curves, request) {
  const asked = request?.traceParams;
  if (asked?.length === 2) return asked;
  const spread = {};
  for (const name of PARAM_NAMES) {
    let low = Infinity;
    let high = -Infinity;
    for (const curve of curves) {
      for (const v of curve.points ?? []) {
        const value = v.params?.[name] ?? 0;
        low = Math.min(low, value);
        high = Math.max(high, value);
      }
    }
    spread[name] = high - low;
  }
  const varying = PARAM_NAMES.filter((n) => spread[n] > 0);
  // omega on the horizontal axis when it varies: the study's (omega, a) plane.
  varying.sort((p, q) => (q === 'omega') - (p === 'omega'));
  return [varying[0] ?? 'omega', varying[1] ?? 'a'];
}

// The datasets of a TraceResult's curves, codimension-2 points and stability region.
function traceDatasets(result, plane) {
  const [px, py] = plane;
  const at = (params) => ({x: params?.[px] ?? 0, y: params?.[py] ?? 0});
  const datasets = [];
  const region = result.region;
  if (region?.polygons?.length) {
    region.polygons.forEach((polygon, i) => {
      const ring = (polygon.vertices ?? []).map((v) => ({x: v.value1 ?? 0, y: v.value2 ?? 0}));
      if (ring.length) ring.push(ring[0]);
      datasets.push({label: 'stable period-1 region', data: ring, showLine: true, fill: 'shape',
        borderColor: 'rgba(42, 157, 143, 0.6)', backgroundColor: 'rgba(42, 157, 143, 0.15)',
        borderWidth: 1, pointRadius: 0, legend: i === 0, order: 1});  // below the curves
    });
  }
  const seen = new Set();
  for (const curve of result.curves ?? []) {
    const key = `${curve.kind} ${curve.period ?? 1}`;
    const label = (curve.period ?? 1) > 1 ? `${curve.kind} (period ${curve.period})` : curve.kind;
    datasets.push(line(label, (curve.points ?? []).map((v) => at(v.params)),
        COLORS[curve.kind] ?? '#555', {dashed: (curve.period ?? 1) > 1, legend: !seen.has(key)}));
    seen.add(key);
  }
  const codim2 = (result.codim2Points ?? []).map((p) => ({...at(p.params),
    label: SPECIAL_LABELS[p.kind] ?? p.kind}));
  datasets.push(markers('codimension-2 points', codim2, COLORS.special, {style: 'triangle'}));
  return datasets;
}

/** The two-parameter map of a TraceResult. */
export function plotTrace(container, result, request) {
  const plane = planeOf(result.curves ?? [], request);
  draw(container, 'trace', traceDatasets(result, plane), plane[0], plane[1]);
}

/**
 * An OptimumResult: the optimum and its margin rectangle in the parameter plane, over the curves
 * of the same box when a trace of it is known (`trace`: a TraceResult or null).
 */
export function plotOptimum(container, result, request, trace) {
  const plane = planeOf(trace?.curves ?? [], request?.trace);
  const [px, py] = plane;
  const datasets = trace ? traceDatasets(trace, plane) : [];
  const x = result.params?.[px] ?? 0;
  const y = result.params?.[py] ?? 0;
  const margin = result.margin ?? [];
  if (margin.length === 2 && !request?.scaled) {
    const [mx, my] = margin;
    datasets.push(line('margin', [{x: x - mx, y: y - my}, {x: x + mx, y: y - my},
      {x: x + mx, y: y + my}, {x: x - mx, y: y + my}, {x: x - mx, y: y - my}], COLORS.optimum));
  }
  datasets.push(markers('optimum', [{x, y, label: `ROP ${Number(result.rop ?? 0).toPrecision(4)}`}],
      COLORS.optimum, {style: 'star', radius: 9}));
  draw(container, 'optimum', datasets, px, py);
}

/** A SimulateResult: the trajectory's p and q against time, else the Poincare samples of p. */
export function plotSimulate(container, result) {
  const trajectory = result.trajectory ?? [];
  if (trajectory.length) {
    draw(container, 'simulate', [
      line('p (bit)', trajectory.map((s) => ({x: s.t ?? 0, y: s.p ?? 0})), COLORS.stable),
      line('q (slider top)', trajectory.map((s) => ({x: s.t ?? 0, y: s.q ?? 0})), COLORS.unstable),
    ], 'time t', 'position');
    return;
  }
  const samples = (result.poincare ?? []).map((s) => ({x: s.period ?? 0, y: s.p ?? 0}));
  draw(container, 'simulate', [markers('p at s = 0', samples, COLORS.stable,
      {radius: 2, labelled: false})], 'forcing period', 'p at the Poincare section');
}

/** A SweepResult: the Poincare samples of p at each value, up and down. */
export function plotSweep(container, result, request) {
  const samples = (points) => (points ?? []).flatMap((point) =>
    (point.samples ?? []).map((s) => ({x: point.value ?? 0, y: s.p ?? 0})));
  draw(container, 'sweep', [
    markers('up', samples(result.up), COLORS.stable, {radius: 2, labelled: false}),
    markers('down', samples(result.down), COLORS.unstable,
        {style: 'crossRot', radius: 3, labelled: false}),
  ], request?.param ?? 'parameter', 'p at the Poincare section');
}

// A colour for `t` in [0, 1] from light yellow (low) to dark blue (high): the ROP of a map of
// two conditions.
function heat(t) {
  const low = [240, 228, 66];
  const high = [31, 63, 153];
  const mix = low.map((l, i) => Math.round(l + (high[i] - l) * Math.min(1, Math.max(0, t))));
  return `rgb(${mix.join(', ')})`;
}

/**
 * An OptimumMapResult. One condition: the optimum's ROP (left axis) and its two trace
 * parameters (right axis) against the condition, one point per cell in condition order; a cell
 * whose optimum was not found or failed is a gap in the lines and a cross on the ROP axis' lowest
 * found value, labelled with its status. Two conditions: one square per cell at its two
 * condition values, coloured by ROP (light low, dark high), crosses where none was found.
 * `query` ({values, answer}: a QueryOptimum answer at those condition values) is marked with a
 * star.
 */
export function plotOptimumMap(container, result, request, query) {
  const over = result.over ?? [];
  const cells = [...(result.cells ?? [])].sort((p, q) => {
    const [pi, qi] = [p.index ?? [], q.index ?? []];
    return (pi[0] ?? 0) - (qi[0] ?? 0) || (pi[1] ?? 0) - (qi[1] ?? 0);
  });
  const found = (cell) => cell.optimum?.status === 'COMPLETED';
  const rops = cells.filter(found).map((cell) => Number(cell.optimum.rop ?? 0));
  const missing = cells.filter((cell) => !found(cell));
  const statusOf = (cell) => cell.optimum?.status ?? 'FAILED';
  const answer = query?.answer?.optimum;
  const traceParams = request?.optimum?.trace?.traceParams?.length === 2 ?
    request.optimum.trace.traceParams : ['omega', 'a'];
  if (over.length === 1) {
    const [condition] = over;
    const at = (cell) => cell.condition?.[0] ?? 0;
    const bottom = rops.length ? Math.min(...rops) : 0;
    const datasets = [
      {...line('ROP', cells.map((cell) => ({x: at(cell),
        y: found(cell) ? Number(cell.optimum.rop ?? 0) : null})), COLORS.optimum),
      pointRadius: 3},
      ...traceParams.map((param, i) => ({...line(`${param} at the optimum`, cells.map((cell) =>
        ({x: at(cell), y: found(cell) ? (cell.optimum.params?.[param] ?? 0) : null})),
      i === 0 ? COLORS.stable : COLORS.period2, {dashed: i === 1}), pointRadius: 3,
      yAxisID: 'y2'})),
      markers('optimum not found / failed', missing.map((cell) => ({x: at(cell), y: bottom,
        label: statusOf(cell)})), COLORS.unstable, {style: 'crossRot', radius: 7}),
    ];
    if (answer) {
      const x = query.values[0];
      datasets.push(markers('query (ROP)', [{x, y: Number(answer.rop ?? 0),
        label: `query ROP ${Number(answer.rop ?? 0).toPrecision(4)}`}], COLORS.special,
      {style: 'star', radius: 10}));
      datasets.push({...markers('query (trace parameters)', traceParams.map((param) => ({x,
        y: answer.params?.[param] ?? 0})), COLORS.special, {style: 'star', radius: 8,
        labelled: false}), yAxisID: 'y2'});
    }
    draw(container, 'optimum-map', datasets, condition, 'ROP at the optimum',
        {y2Title: `optimum's ${traceParams.join(', ')}`});
    return;
  }
  const [c1, c2] = over;
  const low = rops.length ? Math.min(...rops) : 0;
  const high = rops.length ? Math.max(...rops) : 1;
  const points = cells.filter(found).map((cell) => {
    const rop = Number(cell.optimum.rop ?? 0);
    return {x: cell.condition?.[0] ?? 0, y: cell.condition?.[1] ?? 0,
      label: `ROP ${rop.toPrecision(4)}`, color: heat(high > low ? (rop - low) / (high - low) : 1)};
  });
  const datasets = [
    {...markers(`ROP (light ${low.toPrecision(3)} to dark ${high.toPrecision(3)})`, points,
        COLORS.stable, {style: 'rect', radius: 8, labelled: false}),
    backgroundColor: points.map((p) => p.color), borderColor: points.map((p) => p.color)},
    markers('optimum not found / failed', missing.map((cell) => ({x: cell.condition?.[0] ?? 0,
      y: cell.condition?.[1] ?? 0, label: statusOf(cell)})), COLORS.unstable,
    {style: 'crossRot', radius: 7, labelled: false}),
  ];
  if (answer) {
    datasets.push(markers('query', [{x: query.values[0], y: query.values[1],
      label: `ROP ${Number(answer.rop ?? 0).toPrecision(4)}`}], COLORS.special,
    {style: 'star', radius: 10}));
  }
  draw(container, 'optimum-map', datasets, c1, c2);
}

/** Removes the plot. */
export function clearPlot(container) {
  if (chart) chart.destroy();
  chart = null;
  delete container.dataset.kind;
  container.dataset.series = '0';
  container.dataset.points = '0';
}
