#!/usr/bin/python3
"""Keeps proto/openapi.yaml true, with Debian packages only (python3-yaml,
python3-jsonschema):

  - it is a valid OpenAPI 3.1 document: it is validated (JSON Schema 2020-12,
    python3-jsonschema) against the OpenAPI 3.1 schema shipped next to this
    file (schema-3.1.json), every $ref resolves, every Schema Object is a
    valid JSON Schema 2020-12 schema with no unknown keywords, and every
    example matches its schema;
  - every route raysweepd serves (`raysweepd routes`: one `METHOD PATH` per
    line) is in the spec and every route of the spec is served, and the same
    against the routes table of proto/API-NOTES.md;
  - every operation has a unique operationId, every 4xx/5xx response is
    application/problem+json with the Problem schema, and only the health
    routes and the web viewer's static files (/ui, /ui/...) are exempt from
    the bearer scheme.

Prints `ok   <name>` or `FAIL <name>: why` per check and ends with
`test_openapi: N passed, N failed`; exit status 1 when any check failed.

Environment: RSW_BIN_DIR (default build/bin, relative to the repository root)
holds raysweepd. RSW_OPENAPI_SPEC and RSW_OPENAPI_NOTES replace
proto/openapi.yaml and proto/API-NOTES.md (the negative tests of
tests/integration/test_openapi.sh use them). RSW_OPENAPI_ROUTES=notes takes
the served routes from API-NOTES.md instead of the binary (for working on the
spec before the daemon serves a route; never in `make test`).

schema-3.1.json is the OpenAPI Initiative's published schema for OpenAPI
3.1 documents, https://spec.openapis.org/oas/3.1/schema/2022-10-07 (Apache
License 2.0), unmodified.
"""

import json
import os
import re
import subprocess
import sys
import warnings

# jsonschema >= 4.18 deprecates RefResolver; Debian 12 has 4.10, where it is
# the way to resolve '#/components/...' against the whole document.
warnings.filterwarnings("ignore", category=DeprecationWarning)

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
SPEC = os.environ.get("RSW_OPENAPI_SPEC") or os.path.join(ROOT, "proto", "openapi.yaml")
NOTES = os.environ.get("RSW_OPENAPI_NOTES") or os.path.join(ROOT, "proto", "API-NOTES.md")
OAS_SCHEMA = os.path.join(HERE, "schema-3.1.json")
METHODS = ["get", "put", "post", "delete", "options", "head", "patch", "trace"]

passed = 0
failed = 0


def ok(name):
    global passed
    passed += 1
    print(f"ok   {name}", flush=True)


def fail(name, why):
    global failed
    failed += 1
    print(f"FAIL {name}: {why}", flush=True)


def finish():
    print(f"test_openapi: {passed} passed, {failed} failed", flush=True)
    sys.exit(1 if failed else 0)


def check(name, fn):
    """Runs one named check: fn returns a list of problems (empty: pass) or raises."""
    try:
        problems = fn() or []
    except Exception as e:  # a check that cannot run is a failed check
        fail(name, f"{type(e).__name__}: {' | '.join(str(e).splitlines()[:6])}")
        return False
    if problems:
        more = f"; ... ({len(problems)} in all)" if len(problems) > 8 else ""
        fail(name, "; ".join(problems[:8]) + more)
        return False
    ok(name)
    return True


try:
    import yaml
    import jsonschema
    from jsonschema import Draft202012Validator, RefResolver
except ImportError as e:
    fail("deps", f"{e} (install python3-yaml and python3-jsonschema: `make deps`)")
    finish()


# ---- YAML as OpenAPI reads it (YAML 1.2 core schema) -------------------------
# PyYAML implements YAML 1.1: `yes`/`no`/`on`/`off` would be booleans and
# 2024-01-01 a date. OpenAPI documents are YAML 1.2 (js-yaml, which the spec's
# tooling uses): those are strings. Duplicate keys are an error, not
# last-one-wins.
class SpecLoader(yaml.SafeLoader):
    pass


SpecLoader.yaml_implicit_resolvers = {
    k: [(tag, rx) for tag, rx in v if tag not in ("tag:yaml.org,2002:bool", "tag:yaml.org,2002:timestamp")]
    for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
SpecLoader.add_implicit_resolver(
    "tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF")
)


def construct_mapping(loader, node, deep=False):
    loader.flatten_mapping(node)
    out = {}
    for knode, vnode in node.value:
        key = loader.construct_object(knode, deep=deep)
        # JSON keys are strings: `200:` is the key "200".
        if isinstance(key, bool):
            key = "true" if key else "false"
        elif key is None:
            key = "null"
        elif not isinstance(key, str):
            key = str(key)
        if key in out:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", knode.start_mark
            )
        out[key] = loader.construct_object(vnode, deep=deep)
    return out


SpecLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, construct_mapping)


# ---- $ref ------------------------------------------------------------------
def pointer(doc, ref):
    """The node a local $ref ('#/a/b') names; raises KeyError when it does not resolve."""
    if not isinstance(ref, str) or not ref.startswith("#"):
        raise KeyError(f"non-local $ref {ref!r}")
    node = doc
    if ref in ("#", "#/"):
        return node
    if not ref.startswith("#/"):
        raise KeyError(f"$ref {ref!r} is not a JSON pointer")
    for part in ref[2:].split("/"):
        part = part.replace("~1", "/").replace("~0", "~")
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            raise KeyError(f"$ref {ref!r} does not resolve (no {part!r})")
    return node


def deref(doc, obj):
    """Follows $ref chains from obj; raises on a cycle or an unresolved $ref."""
    seen = set()
    while isinstance(obj, dict) and isinstance(obj.get("$ref"), str):
        ref = obj["$ref"]
        if ref in seen:
            raise KeyError(f"$ref cycle at {ref}")
        seen.add(ref)
        obj = pointer(doc, ref)
    return obj


def all_refs(node, where="#"):
    """(location, ref) for every $ref in the document."""
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "$ref":
                yield where, v
            else:
                yield from all_refs(v, f"{where}/{k}")
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from all_refs(v, f"{where}/{i}")


# ---- JSON Schema 2020-12, strictly -----------------------------------------
# ajv's strict mode, which the earlier Node checker used: an unknown keyword
# (a typo such as `minlenght`) is an error, `required` names declared
# properties, no keyword contradicts the schema's `type`, and a tuple
# (prefixItems) is closed. OpenAPI adds
# discriminator, xml, externalDocs and example to the vocabulary.
SUBSCHEMA = {"not", "if", "then", "else", "items", "contains", "additionalProperties", "propertyNames",
             "unevaluatedItems", "unevaluatedProperties", "contentSchema"}
SUBSCHEMA_LIST = {"allOf", "anyOf", "oneOf", "prefixItems"}
SUBSCHEMA_MAP = {"properties", "patternProperties", "$defs", "definitions", "dependentSchemas"}
OTHER = {"$schema", "$id", "$ref", "$anchor", "$dynamicRef", "$dynamicAnchor", "$vocabulary", "$comment",
         "type", "enum", "const", "multipleOf", "maximum", "exclusiveMaximum", "minimum", "exclusiveMinimum",
         "maxLength", "minLength", "pattern", "maxItems", "minItems", "uniqueItems", "maxContains",
         "minContains", "maxProperties", "minProperties", "required", "dependentRequired", "title",
         "description", "default", "deprecated", "readOnly", "writeOnly", "examples", "format",
         "contentEncoding", "contentMediaType",
         "discriminator", "xml", "externalDocs", "example"}
KNOWN = SUBSCHEMA | SUBSCHEMA_LIST | SUBSCHEMA_MAP | OTHER
TYPE_OF = {}
for _k in ("properties", "patternProperties", "additionalProperties", "propertyNames", "required",
           "dependentRequired", "dependentSchemas", "minProperties", "maxProperties", "unevaluatedProperties"):
    TYPE_OF[_k] = "object"
for _k in ("items", "prefixItems", "contains", "minItems", "maxItems", "uniqueItems", "minContains",
           "maxContains", "unevaluatedItems"):
    TYPE_OF[_k] = "array"
for _k in ("minLength", "maxLength", "pattern", "contentEncoding", "contentMediaType", "contentSchema"):
    TYPE_OF[_k] = "string"
for _k in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum", "multipleOf"):
    TYPE_OF[_k] = "number"


def strict_problems(schema, where):
    problems = []
    if isinstance(schema, bool):
        return problems
    if not isinstance(schema, dict):
        return [f"{where} is not a schema"]
    types = schema.get("type")
    types = [types] if isinstance(types, str) else (types or [])
    for k, v in schema.items():
        if k.startswith("x-"):
            continue
        if k not in KNOWN:
            problems.append(f"{where}: unknown keyword {k!r}")
            continue
        want = TYPE_OF.get(k)
        if types and want and not (want in types or (want == "number" and "integer" in types)):
            problems.append(f"{where}: {k!r} applies to {want} but type is {types}")
        if k in SUBSCHEMA:
            problems += strict_problems(v, f"{where}/{k}")
        elif k in SUBSCHEMA_LIST and isinstance(v, list):
            for i, s in enumerate(v):
                problems += strict_problems(s, f"{where}/{k}/{i}")
        elif k in SUBSCHEMA_MAP and isinstance(v, dict):
            for name, s in v.items():
                problems += strict_problems(s, f"{where}/{k}/{name}")
    if isinstance(schema.get("prefixItems"), list):
        n = len(schema["prefixItems"])
        if schema.get("minItems") != n or not (schema.get("items") is False or schema.get("maxItems") == n):
            problems.append(f"{where}: prefixItems without minItems {n} and items: false (an open tuple)")
    props = schema.get("properties")
    if isinstance(schema.get("required"), list) and isinstance(props, dict) and "$ref" not in schema:
        for r in schema["required"]:
            if r not in props and not schema.get("patternProperties") and schema.get("additionalProperties") in (None, False):
                problems.append(f"{where}: required {r!r} is not in properties")
    return problems


def validator(doc, schema):
    # Formats are annotations here, as they were for ajv (validateFormats: false).
    return Draft202012Validator(schema, resolver=RefResolver(base_uri="", referrer=doc))


def errors_text(v, instance):
    errs = sorted(v.iter_errors(instance), key=lambda e: list(e.absolute_path))
    return ", ".join(f"/{'/'.join(map(str, e.absolute_path))} {e.message[:160]}" for e in errs[:3])


# ---- routes ------------------------------------------------------------------
def route_key(method, path):
    """Path templates match whatever their parameters are called: routing only sees the shape."""
    return f"{method.upper()} {re.sub(r'{[^}/]*}', '{}', path)}"


def spec_routes(doc):
    routes = {}
    for path, item in (doc.get("paths") or {}).items():
        for m in METHODS:
            if isinstance(item, dict) and m in item:
                routes[route_key(m, path)] = f"{m.upper()} {path}"
    return routes


def notes_routes():
    routes = {}
    with open(NOTES, encoding="utf-8") as f:
        for line in f:
            m = re.match(r"^\|\s*([A-Z]+)\s*\|\s*(/\S*)\s*\|", line)
            if m:
                routes[route_key(m[1], m[2])] = f"{m[1]} {m[2]}"
    if not routes:
        raise ValueError(f"no routes table found in {NOTES}")
    return routes


def served_routes():
    d = os.environ.get("RSW_BIN_DIR") or "build/bin"
    binary = os.path.join(d if os.path.isabs(d) else os.path.join(ROOT, d), "raysweepd")
    if not os.path.exists(binary):
        raise FileNotFoundError(f"{binary} does not exist (build it with make, or set RSW_BIN_DIR)")
    r = subprocess.run([binary, "routes"], capture_output=True, text=True, timeout=10, stdin=subprocess.DEVNULL)
    if r.returncode != 0:
        err = (r.stderr.strip().splitlines() or [""])[0]
        raise RuntimeError(f"`{binary} routes` failed (status {r.returncode}{': ' + err if err else ''})")
    routes, bad = {}, []
    for line in r.stdout.splitlines():
        if not line.strip():
            continue
        m = re.match(r"^([A-Z]+) (/\S*)$", line.strip())
        if m:
            routes[route_key(m[1], m[2])] = f"{m[1]} {m[2]}"
        else:
            bad.append(json.dumps(line))
    if bad:
        raise ValueError(f"`raysweepd routes` printed lines that are not METHOD PATH: {', '.join(bad[:3])}")
    if not routes:
        raise ValueError("`raysweepd routes` printed no routes")
    return routes


def compare_routes(what, actual, spec):
    problems = [f"{what} {shown} is not in openapi.yaml" for k, shown in actual.items() if k not in spec]
    problems += [f"openapi.yaml {shown} is not {what}" for k, shown in spec.items() if k not in actual]
    return problems


def operations(doc):
    for path, item in (doc.get("paths") or {}).items():
        for m in METHODS:
            if isinstance(item, dict) and isinstance(item.get(m), dict):
                yield path, m, item[m], f"{m.upper()} {path}"


# ---- the document ------------------------------------------------------------
raw = None


def c_parse():
    global raw
    with open(SPEC, encoding="utf-8") as f:
        raw = yaml.load(f, Loader=SpecLoader)
    if not isinstance(raw, dict):
        return [f"{SPEC} is not a YAML mapping"]
    return [] if raw.get("openapi") == "3.1.0" else [f"openapi is {json.dumps(raw.get('openapi'))}, want \"3.1.0\""]


check("spec_parse", c_parse)
if not isinstance(raw, dict):
    finish()


def c_validate():
    with open(OAS_SCHEMA, encoding="utf-8") as f:
        oas = json.load(f)
    Draft202012Validator.check_schema(oas)
    v = Draft202012Validator(oas)
    errors = list(v.iter_errors(raw))
    paths = [tuple(e.absolute_path) for e in errors]
    problems = []
    for e, p in sorted(zip(errors, paths), key=lambda ep: [str(x) for x in ep[1]]):
        # An error inside an object also fails every object around it
        # (unevaluatedProperties): report the innermost only.
        if any(len(q) > len(p) and q[: len(p)] == p for q in paths):
            continue
        problems.append(f"/{'/'.join(map(str, p))}: {e.message[:200]}")
    return problems


check("spec_validate", c_validate)


def c_refs():
    problems = []
    n = 0
    for where, ref in all_refs(raw):
        n += 1
        try:
            deref(raw, {"$ref": ref})
        except KeyError as e:
            problems.append(f"{where}: {e.args[0]}")
    if n == 0:
        problems.append("no $ref found")
    return problems


check("spec_dereference", c_refs)


def c_schemas():
    problems = []
    schemas = (raw.get("components") or {}).get("schemas") or {}
    for name, schema in schemas.items():
        try:
            Draft202012Validator.check_schema(schema)
        except jsonschema.exceptions.SchemaError as e:
            problems.append(f"{name}: /{'/'.join(map(str, e.absolute_path))} {e.message[:160]}")
            continue
        problems += strict_problems(schema, f"components/schemas/{name}")
    for path, m, op, where in operations(raw):
        for i, p in enumerate(op.get("parameters") or []):
            p = deref(raw, p)
            if isinstance(p, dict) and "schema" in p:
                problems += strict_problems(p["schema"], f"{where} parameter {p.get('name', i)}")
    if not schemas:
        problems.append("components/schemas is empty")
    return problems


check("schemas_compile", c_schemas)


def c_named():
    want = ["ServerInfo", "HealthStatus", "SceneDict", "SceneSummary", "SceneInfo", "SceneList", "ParamEntry",
            "ParamTable", "ParamPatch", "PatchResult", "RenderRequest", "FilmJson", "Directions", "JobRequest",
            "Context", "Job", "JobList", "Results", "JobEventContext", "JobEventEnd", "BlobsMissingRequest",
            "BlobsMissingResponse", "Problem"]
    have = (raw.get("components") or {}).get("schemas") or {}
    return [f"components/schemas/{n} is missing" for n in want if n not in have]


check("schemas_named", c_named)


def c_examples():
    """Every example (media types, parameters, named examples) against its schema."""
    problems = []
    n = 0

    def validate(where, schema, example):
        nonlocal n
        if schema is None:
            return
        n += 1
        v = validator(raw, schema)
        if not v.is_valid(example):
            problems.append(f"{where}: {errors_text(v, example)}")

    def walk_content(where, content):
        for mtype, media in (deref(raw, content) or {}).items():
            media = deref(raw, media) or {}
            schema = media.get("schema")
            s = deref(raw, schema) if schema is not None else None
            if "json" not in mtype and not (isinstance(s, dict) and s.get("type") == "string"):
                continue
            if "example" in media:
                validate(f"{where} {mtype} example", schema, media["example"])
            for k, ex in (media.get("examples") or {}).items():
                ex = deref(raw, ex)
                if isinstance(ex, dict) and "value" in ex:
                    validate(f"{where} {mtype} examples.{k}", schema, ex["value"])

    for path, m, op, where in operations(raw):
        for p in op.get("parameters") or []:
            p = deref(raw, p)
            if isinstance(p, dict) and "example" in p:
                validate(f"{where} parameter {p.get('name')}", p.get("schema"), p["example"])
        body = deref(raw, op.get("requestBody"))
        if isinstance(body, dict):
            walk_content(f"{where} request", body.get("content"))
        for status, r in (op.get("responses") or {}).items():
            r = deref(raw, r)
            if isinstance(r, dict):
                walk_content(f"{where} {status}", r.get("content"))
    for name, r in ((raw.get("components") or {}).get("responses") or {}).items():
        r = deref(raw, r)
        if isinstance(r, dict):
            walk_content(f"responses/{name}", r.get("content"))
    for name, schema in ((raw.get("components") or {}).get("schemas") or {}).items():
        if isinstance(schema, dict) and "example" in schema:
            validate(f"components/schemas/{name} example", schema, schema["example"])
    if n == 0:
        problems.append("no examples found")
    return problems


check("examples_valid", c_examples)

# ---- routes ------------------------------------------------------------------
check("routes_notes", lambda: compare_routes("in API-NOTES.md", notes_routes(), spec_routes(raw)))
if os.environ.get("RSW_OPENAPI_ROUTES") == "notes":
    check("routes_served (from API-NOTES.md: RSW_OPENAPI_ROUTES=notes)",
          lambda: compare_routes("served", notes_routes(), spec_routes(raw)))
else:
    check("routes_served", lambda: compare_routes("served by raysweepd", served_routes(), spec_routes(raw)))


# ---- operations --------------------------------------------------------------
def c_operation_ids():
    problems = []
    seen = {}
    for path, m, op, where in operations(raw):
        oid = op.get("operationId")
        if not isinstance(oid, str) or not re.match(r"^[a-z][A-Za-z0-9]*$", oid):
            problems.append(f"{where} has no camelCase operationId")
        elif oid in seen:
            problems.append(f"{where} repeats operationId {oid} of {seen[oid]}")
        else:
            seen[oid] = where
    return problems


check("operation_ids", c_operation_ids)


def c_path_parameters():
    """Every {name} of a path template has a required `in: path` parameter, and back."""
    problems = []
    for path, m, op, where in operations(raw):
        in_path = set(re.findall(r"{([^}/]+)}", path))
        declared = {}
        for p in list(raw["paths"][path].get("parameters") or []) + list(op.get("parameters") or []):
            p = deref(raw, p)
            if isinstance(p, dict) and p.get("in") == "path":
                declared[p.get("name")] = p
        problems += [f"{where}: {{{n}}} has no path parameter" for n in sorted(in_path) if n not in declared]
        for name, p in declared.items():
            if name not in in_path:
                problems.append(f"{where}: path parameter {name} is not in the template")
            elif p.get("required") is not True:
                problems.append(f"{where}: path parameter {name} is not required")
    return problems


check("path_parameters", c_path_parameters)

ERROR_RESPONSES = re.compile(
    r"^(BadRequest|Unauthorized|NotFound|MethodNotAllowed|NotAcceptable|Conflict|PreconditionFailed|"
    r"ContentTooLarge|UnsupportedMediaType|UnprocessableContent|TooManyRequests|Unavailable|GatewayTimeout)$"
)


def c_errors():
    """4xx/5xx (and default) responses: exactly application/problem+json, schema Problem."""
    problems = []

    def check_response(where, resp):
        try:
            r = deref(raw, resp)
        except KeyError:
            r = None
        if not isinstance(r, dict):
            problems.append(f"{where} does not resolve")
            return
        types = list((r.get("content") or {}).keys())
        if types != ["application/problem+json"]:
            problems.append(f"{where} has content {json.dumps(types)}, want [\"application/problem+json\"]")
            return
        schema = r["content"]["application/problem+json"].get("schema") or {}
        if schema.get("$ref") != "#/components/schemas/Problem":
            problems.append(f"{where} schema is not #/components/schemas/Problem")

    n = 0
    for path, m, op, where in operations(raw):
        statuses = list((op.get("responses") or {}).keys())
        if not any(re.match(r"^[23]", s) for s in statuses):
            problems.append(f"{where} has no success response")
        for s in statuses:
            if s == "default" or re.match(r"^[45]", s):
                n += 1
                check_response(f"{where} {s}", op["responses"][s])
        if op.get("security") != [] and "401" not in statuses:
            problems.append(f"{where} needs a token but lists no 401")
    for name, r in ((raw.get("components") or {}).get("responses") or {}).items():
        if ERROR_RESPONSES.match(name):
            check_response(f"components/responses/{name}", r)
    if n == 0:
        problems.append("no error responses found")
    return problems


check("errors_problem_json", c_errors)


def c_security():
    """Bearer everywhere (the document-level requirement) except the health routes, the root and the viewer's files."""
    problems = []
    bearer = ((raw.get("components") or {}).get("securitySchemes") or {}).get("bearer") or {}
    if bearer.get("type") != "http" or bearer.get("scheme") != "bearer":
        problems.append("components/securitySchemes/bearer is not http bearer")
    if raw.get("security") != [{"bearer": []}]:
        problems.append("the document-level security is not [{bearer: []}]")
    for path, m, op, where in operations(raw):
        health = path.startswith("/v1/health/") or path in ("/", "/ui") or path.startswith("/ui/")
        if health and op.get("security") != []:
            problems.append(f"{where} must have security: []")
        if not health and "security" in op:
            problems.append(f"{where} overrides the document's security")
    return problems


check("security_health_exempt", c_security)

finish()
