// The submit forms: one per job kind, each a list of fields that map to the request message of
// proto/drillbif/v1/<kind>.proto (protobuf's JSON names). Prefilled with the reference
// parameters and a small box, so that a submit completes in seconds. The kinds, their routes
// and the choices of the selects come from the server's OpenAPI document (api.ApiDescription);
// a kind it lists with no form here gets a JSON text box for its whole request.

// The reference point of the study (model.proto: an unset field takes the same value).
const PARAMS = [
  ['params.a', 'a', 0.3, 'forcing amplitude'],
  ['params.b', 'b', 0.15, 'static force (weight on bit)'],
  ['params.omega', 'omega', 0.1, 'forcing frequency'],
  ['params.xi', 'xi', 0.05, 'damping ratio of the rock'],
  ['params.g', 'g', 0.02, 'gap at rest'],
  ['params.phi0', 'phi0', 0, 'forcing phase (rad)'],
].map(([path, label, value, hint]) => ({path, label, value, hint, type: 'number'}));

// The choices of a select: `ENUM` those of the field's enum in the OpenAPI document, `PARAMS`
// the fields of ModelParams there (the model's parameter names).
const ENUM = 'enum';
const PARAM_CHOICES = 'params';

// The trace fields (also the optimum's, under "trace."): by default the small box around the
// reference start, omega in [0.05, 0.2] and a in [0.27, 0.32] (about a second of curves).
function traceFields(prefix, {min = '0.05, 0.27', max = '0.2, 0.32'} = {}) {
  return [
    ...PARAMS.map((f) => ({...f, path: prefix + f.path})),
    {path: `${prefix}traceParams`, label: 'trace params', type: 'strings', value: 'omega, a',
      hint: 'two of a, b, omega, xi, g, phi0'},
    {path: `${prefix}min`, label: 'min', type: 'numbers', value: min},
    {path: `${prefix}max`, label: 'max', type: 'numbers', value: max},
    {path: `${prefix}curveSteps`, label: 'curve steps', type: 'select', options: ENUM,
      value: 'CURVE_STEPS_COARSE'},
  ];
}

/** The forms: kind -> {fields}. Field paths are relative to the Submit*Request. */
export const FORMS = {
  simulate: {
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
    fields: [
      ...PARAMS.map((f) => ({...f, path: `request.${f.path}`})),
      {path: 'request.param', label: 'param', type: 'select', options: PARAM_CHOICES, value: 'b'},
      {path: 'request.min', label: 'min', type: 'number', value: 0.1},
      {path: 'request.max', label: 'max', type: 'number', value: 0.2},
      {path: 'request.steps', label: 'steps', type: 'int', value: 21},
      {path: 'request.direction', label: 'direction', type: 'select',
        options: ENUM, value: 'BOTH'},
      {path: 'request.transientPeriods', label: 'transient', type: 'int', value: 200},
      {path: 'request.samplePeriods', label: 'samples', type: 'int', value: 10},
    ],
  },
  continue: {
    fields: [
      ...PARAMS.map((f) => ({...f, path: `request.${f.path}`})),
      {path: 'request.param', label: 'param', type: 'select', options: PARAM_CHOICES, value: 'a'},
      {path: 'request.min', label: 'min', type: 'number', value: 0.25},
      {path: 'request.max', label: 'max', type: 'number', value: 0.4},
      {path: 'request.direction', label: 'direction', type: 'select',
        options: ENUM, value: 'BOTH'},
      {path: 'request.maxSteps', label: 'max steps', type: 'int', value: 2000},
      {path: 'request.followPeriodDoubling', label: 'follow PD', type: 'checkbox', value: false,
        hint: 'also the period-2 branch'},
    ],
  },
  trace: {
    fields: [
      ...traceFields('request.'),
      {path: 'request.region.grid', label: 'region grid', type: 'ints', value: '',
        hint: 'e.g. 41, 41: also the stability region; empty: none'},
    ],
  },
  optimum: {
    fields: [
      ...traceFields('request.trace.'),
      {path: 'request.margin', label: 'margin', type: 'numbers', value: '0.01',
        hint: 'per parameter: one value, or one each'},
      {path: 'request.grid', label: 'grid', type: 'ints', value: '',
        hint: 'nodes per parameter; empty: half-margin spacing'},
    ],
  },
  // The optimum over b in [0.14, 0.16] (5 cells) of the box omega in [0.05, 0.15], a in
  // [0.25, 0.6] on a 41 x 41 grid: a few seconds on two cores.
  'optimum-map': {
    fields: [
      ...traceFields('request.optimum.trace.', {min: '0.05, 0.25', max: '0.15, 0.6'}),
      {path: 'request.optimum.margin', label: 'margin', type: 'numbers', value: '0.01, 0.02',
        hint: 'per trace parameter: one value, or one each'},
      {path: 'request.optimum.grid', label: 'grid', type: 'ints', value: '41, 41',
        hint: 'nodes per trace parameter'},
      {path: 'request.over', label: 'over', type: 'strings', value: 'b',
        hint: 'one or two conditions, neither a trace parameter'},
      {path: 'request.from', label: 'from', type: 'numbers', value: '0.14',
        hint: 'per condition'},
      {path: 'request.to', label: 'to', type: 'numbers', value: '0.16'},
      {path: 'request.steps', label: 'steps', type: 'ints', value: '5',
        hint: 'cells per condition, >= 2'},
    ],
  },
};

// The form of a kind the document lists and this page has no fields for: its whole request.
const JSON_FORM = {
  fields: [{path: 'request', label: 'request (JSON)', type: 'json', value: '{}',
    hint: 'the request message in protobuf\'s JSON mapping (see /openapi.json)'}],
};

/** The form of `kind`: its own, or the JSON box of a kind it does not know. */
export function formOf(kind) {
  return FORMS[kind] ?? JSON_FORM;
}

// The choices of a select field, from the document. Throws when it has none: a form that
// offered made-up values would send what the server does not take.
function choices(field, kind, description) {
  if (Array.isArray(field.options)) return field.options;
  const found = field.options === ENUM ? description.enumValues(kind, field.path) :
    description.fieldsOf('drillbif.v1.ModelParams');
  if (found.length === 0) throw new Error(`/openapi.json: no values for ${kind} ${field.path}`);
  return found;
}

/**
 * The form's inputs for `kind`, in `container` (replacing what it held); the selects' choices
 * from `description` (api.ApiDescription).
 */
export function renderForm(kind, container, description) {
  container.replaceChildren();
  for (const field of formOf(kind).fields) {
    const row = document.createElement('div');
    row.className = 'field';
    const id = `field-${field.path.replaceAll('.', '-')}`;
    const label = document.createElement('label');
    label.htmlFor = id;
    label.textContent = field.label;
    let input;
    if (field.type === 'select') {
      input = document.createElement('select');
      for (const option of choices(field, kind, description)) input.add(new Option(option, option));
      input.value = field.value;
    } else if (field.type === 'json') {
      input = document.createElement('textarea');
      input.rows = 8;
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
 * validation names a bad one. Throws SyntaxError for a JSON box that does not parse.
 */
export function readForm(kind, container) {
  const body = {};
  for (const field of formOf(kind).fields) {
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
      case 'json':
        value = JSON.parse(input.value);
        break;
      default:
        value = input.value;
    }
    setPath(body, field.path, value);
  }
  return body;
}
