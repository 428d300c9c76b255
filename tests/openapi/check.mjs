#!/usr/bin/env node
// Keeps proto/openapi.yaml true:
//   - it is a valid OpenAPI 3.1 document (swagger-parser validates it against
//     the 3.1 meta-schema and resolves every $ref), every schema compiles as
//     JSON Schema 2020-12 (ajv, strict), and every example matches its schema;
//   - every route raysweepd serves (`raysweepd routes`: one `METHOD PATH` per
//     line) is in the spec and every route of the spec is served, and the same
//     against the routes table of proto/API-NOTES.md;
//   - every operation has a unique operationId, every 4xx/5xx response is
//     application/problem+json with the Problem schema, and only the health
//     routes are exempt from the bearer scheme.
// Prints `ok   <name>` or `FAIL <name>: why` per check and ends with
// `test_openapi: N passed, N failed`; exit status 1 when any check failed.
//
// Environment: RSW_BIN_DIR (default build/bin, relative to the repository
// root) holds raysweepd. RSW_OPENAPI_ROUTES=notes takes the served routes
// from API-NOTES.md instead of the binary (for working on the spec before
// the daemon has the `routes` command; never in `make test`).

import { execFileSync } from 'node:child_process';
import { existsSync, readFileSync } from 'node:fs';
import { dirname, isAbsolute, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const root = resolve(here, '..', '..');
const specPath = resolve(root, 'proto', 'openapi.yaml');
const notesPath = resolve(root, 'proto', 'API-NOTES.md');
const METHODS = ['get', 'put', 'post', 'delete', 'options', 'head', 'patch', 'trace'];

let passed = 0;
let failed = 0;
function ok(name) {
  passed++;
  console.log(`ok   ${name}`);
}
function fail(name, why) {
  failed++;
  console.log(`FAIL ${name}: ${why}`);
}
function finish() {
  console.log(`test_openapi: ${passed} passed, ${failed} failed`);
  process.exit(failed ? 1 : 0);
}
// Runs one named check: fn returns a list of problems (empty: pass) or throws.
async function check(name, fn) {
  try {
    const problems = (await fn()) || [];
    if (problems.length === 0) ok(name);
    else fail(name, problems.slice(0, 8).join('; ') + (problems.length > 8 ? `; ... (${problems.length} in all)` : ''));
  } catch (e) {
    fail(name, e && e.message ? e.message.split('\n').slice(0, 6).join(' | ') : String(e));
  }
}

// The validator lives in tests/openapi/node_modules (npm ci --prefix
// tests/openapi, which `make deps` runs); say so plainly when it is absent.
let SwaggerParser, Ajv2020;
try {
  SwaggerParser = (await import('@apidevtools/swagger-parser')).default;
  Ajv2020 = (await import('ajv/dist/2020.js')).default;
} catch (e) {
  fail('deps', `cannot load the OpenAPI validator (${e.code || e.message}); run \`npm ci --prefix tests/openapi\` (or \`make deps\`)`);
  finish();
}

// Path templates match whatever their parameters are called: routing only
// sees the shape of the path.
const routeKey = (method, path) => `${method.toUpperCase()} ${path.replace(/\{[^}/]*\}/g, '{}')}`;

function specRoutes(doc) {
  const routes = new Map();
  for (const [path, item] of Object.entries(doc.paths || {}))
    for (const m of METHODS) if (item[m]) routes.set(routeKey(m, path), `${m.toUpperCase()} ${path}`);
  return routes;
}

// Rows of the "Routes" table: | METHOD | /path | ok | notes |
function notesRoutes() {
  const routes = new Map();
  for (const line of readFileSync(notesPath, 'utf8').split('\n')) {
    const m = /^\|\s*([A-Z]+)\s*\|\s*(\/\S*)\s*\|/.exec(line);
    if (m) routes.set(routeKey(m[1], m[2]), `${m[1]} ${m[2]}`);
  }
  if (routes.size === 0) throw new Error(`no routes table found in ${notesPath}`);
  return routes;
}

function servedRoutes() {
  const dir = process.env.RSW_BIN_DIR || 'build/bin';
  const bin = resolve(isAbsolute(dir) ? dir : resolve(root, dir), 'raysweepd');
  if (!existsSync(bin)) throw new Error(`${bin} does not exist (build it with make, or set RSW_BIN_DIR)`);
  let out;
  try {
    out = execFileSync(bin, ['routes'], { encoding: 'utf8', timeout: 10000, stdio: ['ignore', 'pipe', 'pipe'] });
  } catch (e) {
    const err = (e.stderr || '').toString().trim().split('\n')[0];
    throw new Error(`\`${bin} routes\` failed (status ${e.status ?? e.signal}${err ? `: ${err}` : ''})`);
  }
  const routes = new Map();
  const bad = [];
  for (const line of out.split('\n')) {
    if (line.trim() === '') continue;
    const m = /^([A-Z]+) (\/\S*)$/.exec(line.trim());
    if (m) routes.set(routeKey(m[1], m[2]), `${m[1]} ${m[2]}`);
    else bad.push(JSON.stringify(line));
  }
  if (bad.length) throw new Error(`\`raysweepd routes\` printed lines that are not METHOD PATH: ${bad.slice(0, 3).join(', ')}`);
  if (routes.size === 0) throw new Error('`raysweepd routes` printed no routes');
  return routes;
}

function compareRoutes(what, actual, spec) {
  const problems = [];
  for (const [k, shown] of actual) if (!spec.has(k)) problems.push(`${what} ${shown} is not in openapi.yaml`);
  for (const [k, shown] of spec) if (!actual.has(k)) problems.push(`openapi.yaml ${shown} is not ${what}`);
  return problems;
}

function operations(doc) {
  const ops = [];
  for (const [path, item] of Object.entries(doc.paths || {}))
    for (const m of METHODS) if (item[m]) ops.push({ path, method: m, op: item[m], where: `${m.toUpperCase()} ${path}` });
  return ops;
}

// Follow a local $ref ('#/a/b') inside the parsed (not dereferenced) document.
function deref(doc, obj) {
  const seen = new Set();
  while (obj && typeof obj.$ref === 'string') {
    if (seen.has(obj.$ref)) throw new Error(`$ref cycle at ${obj.$ref}`);
    seen.add(obj.$ref);
    if (!obj.$ref.startsWith('#/')) throw new Error(`non-local $ref ${obj.$ref}`);
    obj = obj.$ref
      .slice(2)
      .split('/')
      .map((s) => s.replace(/~1/g, '/').replace(/~0/g, '~'))
      .reduce((o, k) => (o == null ? undefined : o[k]), doc);
  }
  return obj;
}

function hasRef(v, seen = new Set()) {
  if (v === null || typeof v !== 'object' || seen.has(v)) return false;
  seen.add(v);
  if (Object.prototype.hasOwnProperty.call(v, '$ref')) return true;
  return Object.values(v).some((x) => hasRef(x, seen));
}

function newAjv() {
  // strict: unknown keywords (typos such as `minlenght`) are errors. Formats
  // are annotations here (no format plugin); OpenAPI's own schema keywords
  // are declared as vocabulary.
  const ajv = new Ajv2020({ strict: true, allowUnionTypes: true, validateFormats: false, allErrors: true });
  ajv.addVocabulary(['discriminator', 'xml', 'externalDocs', 'example']);
  return ajv;
}

// ---- the document ------------------------------------------------------------
let raw = null;
let api = null;

await check('spec_parse', async () => {
  raw = await SwaggerParser.parse(specPath);
  return raw.openapi === '3.1.0' ? [] : [`openapi is ${JSON.stringify(raw.openapi)}, want "3.1.0"`];
});
if (!raw) finish();

await check('spec_validate', async () => {
  await SwaggerParser.validate(specPath);
  return [];
});

await check('spec_dereference', async () => {
  api = await SwaggerParser.dereference(specPath);
  return hasRef(api) ? ['a $ref is left after dereferencing'] : [];
});

await check('schemas_compile', () => {
  const ajv = newAjv();
  const problems = [];
  const schemas = (api || raw).components?.schemas || {};
  if (!api) throw new Error('no dereferenced document');
  for (const [name, schema] of Object.entries(schemas)) {
    try {
      ajv.compile(schema);
    } catch (e) {
      problems.push(`${name}: ${e.message}`);
    }
  }
  return problems;
});

await check('schemas_named', () => {
  const want = [
    'ServerInfo', 'HealthStatus', 'SceneDict', 'SceneSummary', 'SceneInfo', 'SceneList', 'ParamEntry',
    'ParamTable', 'ParamPatch', 'PatchResult', 'RenderRequest', 'FilmJson', 'Directions', 'JobRequest',
    'Context', 'Job', 'JobList', 'Results', 'JobEventContext', 'JobEventEnd', 'BlobsMissingRequest',
    'BlobsMissingResponse', 'Problem',
  ];
  const have = raw.components?.schemas || {};
  return want.filter((n) => !have[n]).map((n) => `components/schemas/${n} is missing`);
});

// Every example (media types, parameters, headers, schemas) against its schema.
await check('examples_valid', () => {
  if (!api) throw new Error('no dereferenced document');
  const ajv = newAjv();
  const problems = [];
  let n = 0;
  const validate = (where, schema, example) => {
    if (!schema || example === undefined) return;
    n++;
    const v = ajv.compile(schema);
    if (!v(example)) problems.push(`${where}: ${ajv.errorsText(v.errors)}`);
  };
  const walkContent = (where, content) => {
    for (const [type, media] of Object.entries(content || {})) {
      if (!/json/.test(type) && media.schema?.type !== 'string') continue;
      validate(`${where} ${type} example`, media.schema, media.example);
      for (const [k, ex] of Object.entries(media.examples || {})) validate(`${where} ${type} examples.${k}`, media.schema, ex.value);
    }
  };
  for (const { where, op } of operations(api)) {
    for (const p of op.parameters || []) validate(`${where} parameter ${p.name}`, p.schema, p.example);
    walkContent(`${where} request`, op.requestBody?.content);
    for (const [status, r] of Object.entries(op.responses || {})) walkContent(`${where} ${status}`, r.content);
  }
  for (const [name, r] of Object.entries(api.components?.responses || {})) walkContent(`responses/${name}`, r.content);
  if (n === 0) problems.push('no examples found');
  return problems;
});

// ---- routes ------------------------------------------------------------------
await check('routes_notes', () => compareRoutes('in API-NOTES.md', notesRoutes(), specRoutes(raw)));

if (process.env.RSW_OPENAPI_ROUTES === 'notes')
  await check('routes_served (from API-NOTES.md: RSW_OPENAPI_ROUTES=notes)', () =>
    compareRoutes('served', notesRoutes(), specRoutes(raw)));
else await check('routes_served', () => compareRoutes('served by raysweepd', servedRoutes(), specRoutes(raw)));

// ---- operations --------------------------------------------------------------
await check('operation_ids', () => {
  const problems = [];
  const seen = new Map();
  for (const { where, op } of operations(raw)) {
    if (typeof op.operationId !== 'string' || !/^[a-z][A-Za-z0-9]*$/.test(op.operationId))
      problems.push(`${where} has no camelCase operationId`);
    else if (seen.has(op.operationId)) problems.push(`${where} repeats operationId ${op.operationId} of ${seen.get(op.operationId)}`);
    else seen.set(op.operationId, where);
  }
  return problems;
});

// swagger-parser checks 3.1 documents against the meta-schema only, so the
// path templates and their parameters are matched here: every {name} has a
// required `in: path` parameter and every path parameter is in the template.
await check('path_parameters', () => {
  const problems = [];
  for (const { path, where, op } of operations(raw)) {
    const inPath = new Set([...path.matchAll(/\{([^}/]+)\}/g)].map((m) => m[1]));
    const declared = new Map();
    for (const p of [...(raw.paths[path].parameters || []), ...(op.parameters || [])].map((p) => deref(raw, p)))
      if (p?.in === 'path') declared.set(p.name, p);
    for (const name of inPath) if (!declared.has(name)) problems.push(`${where}: {${name}} has no path parameter`);
    for (const [name, p] of declared) {
      if (!inPath.has(name)) problems.push(`${where}: path parameter ${name} is not in the template`);
      else if (p.required !== true) problems.push(`${where}: path parameter ${name} is not required`);
    }
  }
  return problems;
});

// 4xx/5xx (and default) responses, of operations and of components/responses:
// exactly application/problem+json, schema Problem.
await check('errors_problem_json', () => {
  const problems = [];
  const checkResponse = (where, resp) => {
    const r = deref(raw, resp);
    if (!r) return problems.push(`${where} does not resolve`);
    const types = Object.keys(r.content || {});
    if (types.length !== 1 || types[0] !== 'application/problem+json')
      return problems.push(`${where} has content ${JSON.stringify(types)}, want ["application/problem+json"]`);
    const schema = r.content['application/problem+json'].schema;
    if (!schema || schema.$ref !== '#/components/schemas/Problem') problems.push(`${where} schema is not #/components/schemas/Problem`);
  };
  const isError = (status) => status === 'default' || /^[45]/.test(status);
  let n = 0;
  for (const { where, op } of operations(raw)) {
    const statuses = Object.keys(op.responses || {});
    if (!statuses.some((s) => /^[23]/.test(s))) problems.push(`${where} has no success response`);
    for (const s of statuses.filter(isError)) n++, checkResponse(`${where} ${s}`, op.responses[s]);
    if (op.security?.length !== 0 && !statuses.includes('401')) problems.push(`${where} needs a token but lists no 401`);
  }
  for (const [name, r] of Object.entries(raw.components?.responses || {}))
    if (/^(BadRequest|Unauthorized|NotFound|MethodNotAllowed|NotAcceptable|Conflict|PreconditionFailed|ContentTooLarge|UnsupportedMediaType|UnprocessableContent|TooManyRequests|Unavailable|GatewayTimeout)$/.test(name))
      checkResponse(`components/responses/${name}`, r);
  if (n === 0) problems.push('no error responses found');
  return problems;
});

// Bearer everywhere (the document-level requirement) except the health routes.
await check('security_health_exempt', () => {
  const problems = [];
  const schemes = raw.components?.securitySchemes || {};
  if (schemes.bearer?.type !== 'http' || schemes.bearer?.scheme !== 'bearer') problems.push('components/securitySchemes/bearer is not http bearer');
  if (JSON.stringify(raw.security) !== JSON.stringify([{ bearer: [] }])) problems.push('the document-level security is not [{bearer: []}]');
  for (const { path, where, op } of operations(raw)) {
    const health = path.startsWith('/v1/health/');
    if (health && !(Array.isArray(op.security) && op.security.length === 0)) problems.push(`${where} must have security: []`);
    if (!health && op.security !== undefined) problems.push(`${where} overrides the document's security`);
  }
  return problems;
});

finish();
