# The socket service: its unit tests are in daemon_tests
# (unit/daemon/protocol_test.cpp, unit/daemon/socket_service_test.cpp).
#
# protocol.schema: docs/protocol.schema.json is a valid draft 2020-12 schema,
# and every example line in docs/protocol.md, a few requests and one line of
# every kind from the server's own encoders (daemon_tests,
# ProtocolSamples.Write) validate against it. Uses the `jsonschema` module when
# /usr/bin/python3 has it, else the small validator below (the keywords the
# schema uses); not defined without /usr/bin/python3.
set(SCALED_PROTOCOL_CHECK ${CMAKE_CURRENT_BINARY_DIR}/protocol_schema_check.py)
file(WRITE ${SCALED_PROTOCOL_CHECK} [=[
import json, os, re, subprocess, sys, tempfile

schema_path, doc_path, tests_bin = sys.argv[1:4]
schema = json.load(open(schema_path))
defs = schema.get("$defs", {})
KNOWN = {"$schema", "$ref", "$defs", "title", "description", "default", "type", "const", "enum",
         "required", "properties", "additionalProperties", "items", "minItems", "maxItems",
         "minimum", "minLength", "oneOf"}
TYPES = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None)}


def is_type(v, t):
    if t == "integer":
        return isinstance(v, int) and not isinstance(v, bool)
    if t == "number":
        return isinstance(v, (int, float)) and not isinstance(v, bool)
    return isinstance(v, TYPES[t])


def check(v, s, where):
    unknown = set(s) - KNOWN
    if unknown:
        return [f"schema at {where} uses unsupported keywords {sorted(unknown)}"]
    if "$ref" in s:
        return check(v, defs[s["$ref"].split("/")[-1]], where)
    errs = []
    if "type" in s:
        ts = s["type"] if isinstance(s["type"], list) else [s["type"]]
        if not any(is_type(v, t) for t in ts):
            return [f"{where}: {v!r} is not of type {ts}"]
    if "const" in s and v != s["const"]:
        errs.append(f"{where}: {v!r} != {s['const']!r}")
    if "enum" in s and v not in s["enum"]:
        errs.append(f"{where}: {v!r} not in {s['enum']}")
    if "oneOf" in s:
        n = sum(1 for sub in s["oneOf"] if not check(v, sub, where))
        if n != 1:
            errs.append(f"{where}: matches {n} of oneOf (must be 1)")
    if isinstance(v, dict):
        for k in s.get("required", []):
            if k not in v:
                errs.append(f"{where}: missing {k}")
        props = s.get("properties", {})
        for k, x in v.items():
            if k in props:
                errs += check(x, props[k], f"{where}.{k}")
            elif s.get("additionalProperties", True) is False:
                errs.append(f"{where}: unexpected member {k}")
    if isinstance(v, list):
        if len(v) < s.get("minItems", 0) or len(v) > s.get("maxItems", len(v)):
            errs.append(f"{where}: {len(v)} items")
        if "items" in s:
            for i, x in enumerate(v):
                errs += check(x, s["items"], f"{where}[{i}]")
    if isinstance(v, str) and len(v) < s.get("minLength", 0):
        errs.append(f"{where}: too short")
    if is_type(v, "number") and "minimum" in s and v < s["minimum"]:
        errs.append(f"{where}: {v} < {s['minimum']}")
    return errs


try:
    import jsonschema
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    def validate(v):
        return [e.message for e in validator.iter_errors(v)]
    print("using jsonschema")
except ImportError:
    def validate(v):
        return check(v, schema, "$")
    print("using the built-in validator")

lines = []
text = open(doc_path).read()
for block in re.findall(r"```json\n(.*?)```", text, re.S):
    lines += [("docs/protocol.md", l) for l in block.splitlines() if l.strip()]
for req in ['{"cmd":"poll"}', '{"cmd":"watch","enable":false}', '{"cmd":"status"}',
            '{"cmd":"posterior"}', '{"cmd":"objects"}', '{"cmd":"pose"}',
            '{"cmd":"watch","enable":false,"pose":true}', '{"cmd":"set_gravity","down":[0,1,0]}']:
    lines.append(("request", req))
with tempfile.TemporaryDirectory() as tmp:
    samples = os.path.join(tmp, "samples.jsonl")
    env = dict(os.environ, SCALED_PROTOCOL_SAMPLES=samples)
    run = subprocess.run([tests_bin, "--gtest_filter=ProtocolSamples.Write"], env=env,
                         capture_output=True, text=True)
    if run.returncode != 0 or not os.path.exists(samples):
        print(run.stdout, run.stderr)
        sys.exit("ProtocolSamples.Write failed")
    lines += [("encoder", l) for l in open(samples).read().splitlines()]

failed = 0
classes = set()
for origin, line in lines:
    msg = json.loads(line)
    classes.add(msg.get("class", "request"))
    errs = validate(msg)
    if errs:
        failed += 1
        print(f"{origin}: {line}\n  " + "\n  ".join(errs))
# Lines the schema must reject.
for bad in ['{"class":"SCALE"}', '{"class":"WATCH","enable":1}', '{"class":"NOPE"}',
            '{"cmd":"set_gravity","down":[0,1]}',
            '{"class":"OBJECTS","epoch":0,"frame_id":-1,"model":"paper"}',
            '{"class":"OBJECTS","epoch":0,"frame_id":-1,"model":"other","objects":[]}',
            '{"cmd":"watch","pose":1}',
            '{"class":"WATCH","enable":true,"pose":"yes"}']:
    if not validate(json.loads(bad)):
        failed += 1
        print(f"accepted a bad line: {bad}")
# STATUS.window_ba (proto_minor 5) broken in turn, from the first STATUS line
# that has one.
with_window = [json.loads(l) for _, l in lines if '"window_ba"' in l and '"STATUS"' in l]
if not with_window:
    failed += 1
    print("no STATUS line with window_ba")
else:
    for name, breaks in [("an unknown estimated name", lambda w: w.update(estimated=["f"])),
                         ("an extra member in last", lambda w: w["last"].update(x=1)),
                         ("no last", lambda w: w.pop("last")),
                         ("a string readout", lambda w: w.update(rolling_shutter_s="25 ms"))]:
        bad = json.loads(json.dumps(with_window[0]))
        breaks(bad["window_ba"])
        if not validate(bad):
            failed += 1
            print(f"accepted STATUS.window_ba with {name}")
missing = {"VERSION", "SCALE", "STATUS", "POSTERIOR", "OBJECTS", "POSE", "WATCH", "ACK",
           "ERROR", "request"} - classes
if missing:
    failed += 1
    print("no sample of", sorted(missing))
print(f"{len(lines)} lines checked, {failed} failures")
sys.exit(1 if failed else 0)
]=])

if(EXISTS /usr/bin/python3)
  add_test(NAME protocol.schema
    COMMAND /usr/bin/python3 ${SCALED_PROTOCOL_CHECK}
      ${PROJECT_SOURCE_DIR}/docs/protocol.schema.json ${PROJECT_SOURCE_DIR}/docs/protocol.md
      $<TARGET_FILE:daemon_tests>)
  set_tests_properties(protocol.schema PROPERTIES LABELS "unit;daemon" SKIP_RETURN_CODE 77)
endif()
