// The submit forms: one per job kind, each a list of fields that map to the request message of
// proto/drillbif/v1/<kind>.proto (protobuf's JSON names). Prefilled with the reference
// parameters and a small box, so that a submit completes in seconds.

// The reference point of the study (model.proto: an unset field takes the same value).
const PARAMS = [
  ['params.a', 'a', 0.3, 'forcing amplitude'],
  ['params.b', 'b', 0.15, 'static force (weight on bit)'],
  ['params.omega', 'omega', 0.1, 'forcing frequency'],
  ['params.xi', 'xi', 0.05, 'damping ratio of the rock'],
  ['params.g', 'g', 0.02, 'gap at rest'],
  ['params.phi0', 'phi0', 0, 'forcing phase (rad)'],
].map(([path, label, value, hint]) => ({path, label, value, hint, type: 'number'}));

const PARAM_NAMES = ['a', 'b', 'omega', 'xi', 'g', 'phi0'];

// The trace fields (also the optimum's, under "trace."): the small box around the reference
// start, omega in [0.05, 0.2] and a in [0.27, 0.32] (about a second of curves).
function traceFields(prefix) {
  return [
    ...PARAMS.map((f) => ({...f, path: prefix + f.path})),
    {path: `${prefix}traceParams`, label: 'trace params', type: 'strings', value: 'omega, a',
      hint: 'two of a, b, omega, xi, g, phi0'},
    {path: `${prefix}min`, label: 'min', type: 'numbers', value: '0.05, 0.27'},
    {path: `${prefix}max`, label: 'max', type: 'numbers', value: '0.2, 0.32'},
    {path: `${prefix}curveSteps`, label: 'curve steps', type: 'select',
      options: ['CURVE_STEPS_FINE', 'CURVE_STEPS_COARSE'], value: 'CURVE_STEPS_FINE'},
  ];
}

/** The forms: kind -> {route, fields}. Field paths are relative to the Submit*Request. */
export const FORMS = {
  simulate: {
    route: '/v1/jobs:simulate',
    fields: [
      ...PARAMS.map((f) => ({...f, path: `request.${f.path}`})),
      {path: 'request.transientPeriods', label: 'transient', type: 'int', value: 500,
        hint: 'forcing periods discarded'},
      {path: 'request.samplePeriods', label: 'window', type: 'int', value: 10,
        hint: 'forcing periods recorded'},
      {path: 'request.outputs.trajectoryDt', label: 'trajectory dt', type: 'number', value: 0.5,
        hint: '0: Poincare samples only'},
      {path: 'request.outputs.poincare', label: 'Poincare', type: 'checkbox', value: true},
      {path: 'request.outputs.measures', label: 'measures', type: 'checkbox', value: true},
    ],
  },
  sweep: {
    route: '/v1/jobs:sweep',
    fields: [
      ...PARAMS.map((f) => ({...f, path: `request.${f.path}`})),
      {path: 'request.param', label: 'param', type: 'select', options: PARAM_NAMES, value: 'b'},
      {path: 'request.min', label: 'min', type: 'number', value: 0.1},
      {path: 'request.max', label: 'max', type: 'number', value: 0.2},
      {path: 'request.steps', label: 'steps', type: 'int', value: 21},
      {path: 'request.direction', label: 'direction', type: 'select',
        options: ['UP', 'DOWN', 'BOTH'], value: 'BOTH'},
      {path: 'request.transientPeriods', label: 'transient', type: 'int', value: 200},
      {path: 'request.samplePeriods', label: 'samples', type: 'int', value: 10},
    ],
  },
  continue: {
    route: '/v1/jobs:continue',
    fields: [
      ...PARAMS.map((f) => ({...f, path: `request.${f.path}`})),
      {path: 'request.param', label: 'param', type: 'select', options: PARAM_NAMES, value: 'a'},
      {path: 'request.min', label: 'min', type: 'number', value: 0.25},
      {path: 'request.max', label: 'max', type: 'number', value: 0.4},
      {path: 'request.direction', label: 'direction', type: 'select',
        options: ['BOTH', 'INCREASING', 'DECREASING'], value: 'BOTH'},
      {path: 'request.maxSteps', label: 'max steps', type: 'int', value: 2000},
      {path: 'request.followPeriodDoubling', label: 'follow PD', type: 'checkbox', value: false,
        hint: 'also the period-2 branch'},
    ],
  },
  trace: {
    route: '/v1/jobs:trace',
    fields: [
      ...traceFields('request.'),
      {path: 'request.region.grid', label: 'region grid', type: 'ints', value: '',
        hint: 'e.g. 41, 41: also the stability region; empty: none'},
    ],
  },
  optimum: {
    route: '/v1/jobs:optimum',
    fields: [
      ...traceFields('request.trace.'),
      {path: 'request.margin', label: 'margin', type: 'numbers', value: '0.01',
        hint: 'per parameter: one value, or one each'},
      {path: 'request.grid', label: 'grid', type: 'ints', value: '',
        hint: 'nodes per parameter; empty: half-margin spacing'},
    ],
  },
};

/** The form's inputs for `kind`, in `container` (replacing what it held). */
export function renderForm(kind, container) {
  container.replaceChildren();
  for (const field of FORMS[kind].fields) {
    const row = document.createElement('div');
    row.className = 'field';
    const id = `field-${field.path.replaceAll('.', '-')}`;
    const label = document.createElement('label');
    label.htmlFor = id;
    label.textContent = field.label;
    let input;
    if (field.type === 'select') {
      input = document.createElement('select');
      for (const option of field.options) input.add(new Option(option, option));
      input.value = field.value;
    } else {
      input = document.createElement('input');
      if (field.type === 'checkbox') {
        input.type = 'checkbox';
        input.checked = field.value;
      } else {
        input.type = field.type === 'number' || field.type === 'int' ? 'number' : 'text';
        if (input.type === 'number') input.step = 'any';
        input.value = String(field.value);
      }
    }
    input.id = id;
    input.name = field.path;
    row.append(label, input);
    if (field.hint) {
      const hint = document.createElement('span');
      hint.className = 'hint';
      hint.textContent = field.hint;
      row.append(hint);
    }
    container.append(row);
  }
}

function setPath(object, path, value) {
  const keys = path.split('.');
  let node = object;
  for (const key of keys.slice(0, -1)) node = node[key] ??= {};
  node[keys.at(-1)] = value;
}

function splitList(text) {
  return text.split(',').map((s) => s.trim()).filter((s) => s !== '');
}

/**
 * The Submit*Request of the form of `kind` read from `container`. Empty fields are left out
 * (the server then takes its default); numbers are sent as typed, so that the server's
 * validation names a bad one.
 */
export function readForm(kind, container) {
  const body = {};
  for (const field of FORMS[kind].fields) {
    const input = container.querySelector(`[name="${field.path}"]`);
    let value;
    switch (field.type) {
      case 'checkbox':
        value = input.checked;
        break;
      case 'number':
      case 'int':
        if (input.value.trim() === '') continue;
        value = Number(input.value);
        break;
      case 'numbers':
      case 'ints':
        value = splitList(input.value).map(Number);
        if (value.length === 0) continue;
        break;
      case 'strings':
        value = splitList(input.value);
        break;
      default:
        value = input.value;
    }
    setPath(body, field.path, value);
  }
  return body;
}
