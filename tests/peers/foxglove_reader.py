#!/usr/bin/env python3
"""An independent reader checks a `landing run --record` MCAP file the way Foxglove reads it.

Foxglove's own Python packages (not this project's code) read every message of every
channel: `mcap` (the MCAP reader, chunk CRCs checked) and `foxglove-schemas-protobuf`
(the protobuf classes Foxglove ships). For each channel:

- protobuf (`foxglove.<Type>`): the FileDescriptorSet stored in the file must be,
  file by file, the descriptors Foxglove ships for that type (every message, field
  name, number, label, type, type name, enum and option; the only leeway is a
  `json_name` equal to protoc's default, which protoc writes and Python's descriptors
  leave out), closed under its dependencies, and buildable on its own; every message
  decodes with the shipped class, without unknown fields, and passes a sanity check of
  its type (JPEG bytes, image sizes, the transform tree's frames, entity frames, log
  text);
- JSON: the schema is a JSON Schema object; every message is a JSON object (no NaN
  or Infinity) whose keys are among the schema's `properties`, at every level, and
  whose values have the types, array lengths and items the schema says.

The file must have messages, a summary whose statistics match what was read, and the
`landing` metadata record with a git revision and the graph.

Usage: foxglove_reader.py FILE.mcap [--expect-raw-images]
"""
import argparse
import difflib
import importlib
import json
import math
import re
import sys
from collections import OrderedDict

try:
    from mcap.reader import make_reader
    from google.protobuf import descriptor_pb2, descriptor_pool
    from google.protobuf.unknown_fields import UnknownFieldSet
    import foxglove_schemas_protobuf
except ImportError as e:  # pragma: no cover - what CI prints on a machine without them
    print(f"foxglove reader: FAILED: {e}: python3 -m pip install mcap foxglove-schemas-protobuf",
          flush=True)
    sys.exit(1)

# The transform tree the recorder writes (processes/recorder/src/visual.rs).
TF_FRAMES = {"world", "body", "camera", "depth_camera", "pad_observed", "pad"}
# The Foxglove type each known topic must carry; other foxglove.* topics get the
# generic checks of their type.
EXPECTED_TYPES = {
    "/camera/frame": {"CompressedImage", "RawImage"},
    "/sim/depth": {"RawImage"},
    "/tf": {"FrameTransforms"},
    "/scene/map": {"SceneUpdate"},
    "/scene/trajectory": {"SceneUpdate"},
    "/scene/pad": {"SceneUpdate"},
    "/scene/truth": {"SceneUpdate"},
    "/log": {"Log"},
}
# Bytes per pixel of the RawImage encodings Foxglove's Image panel decodes.
BYTES_PER_PIXEL = {
    "mono8": 1, "8UC1": 1, "bayer_rggb8": 1, "bayer_bggr8": 1, "bayer_gbrg8": 1,
    "bayer_grbg8": 1, "rgb8": 3, "bgr8": 3, "8UC3": 3, "rgba8": 4, "bgra8": 4,
    "mono16": 2, "16UC1": 2, "32FC1": 4, "uyvy": 2, "yuyv": 2, "yuv422": 2,
    "yuv422_yuy2": 2,
}
# The `landing` metadata record's keys (`landing run` adds scenario, seed, mode).
METADATA_KEYS = ("git_revision", "version", "graph", "graph_file", "config", "config_file")
# JSON Schema keywords that only annotate.
ANNOTATIONS = {"$schema", "$id", "$comment", "title", "description", "default", "examples",
               "format", "readOnly", "writeOnly", "deprecated", "$defs", "definitions"}


class Failure(Exception):
    pass


def fail(msg):
    raise Failure(msg)


# ---------------------------------------------------------------- protobuf schemas

def default_json_name(name):
    """protoc's json_name of a field: underscores dropped, the next letter capitalised."""
    out, upper = [], False
    for c in name:
        if c == "_":
            upper = True
        elif upper:
            out.append(c.upper())
            upper = False
        else:
            out.append(c)
    return "".join(out)


def normalized(fdp):
    """A copy of a FileDescriptorProto without the json_names protoc would have given.

    protoc writes every field's json_name into a descriptor set; the descriptors
    embedded in Python's generated code leave it out. A json_name that differs from the
    default is kept, so a renamed JSON field still shows as a difference."""
    out = descriptor_pb2.FileDescriptorProto()
    out.CopyFrom(fdp)

    def strip(msg):
        for f in list(msg.field) + list(msg.extension):
            if f.HasField("json_name") and f.json_name == default_json_name(f.name):
                f.ClearField("json_name")
        for n in msg.nested_type:
            strip(n)

    for m in out.message_type:
        strip(m)
    for f in out.extension:
        if f.HasField("json_name") and f.json_name == default_json_name(f.name):
            f.ClearField("json_name")
    return out


def shipped_class(type_name):
    """The class foxglove_schemas_protobuf ships for `Type` (foxglove.Type)."""
    try:
        module = importlib.import_module(f"foxglove_schemas_protobuf.{type_name}_pb2")
    except ImportError:
        return None
    return getattr(module, type_name, None)


def shipped_files(cls):
    """The FileDescriptorProtos of cls's file and all it imports, by name."""
    files = OrderedDict()

    def add(fd):
        if fd.name in files:
            return
        for dep in fd.dependencies:
            add(dep)
        p = descriptor_pb2.FileDescriptorProto()
        fd.CopyToProto(p)
        files[fd.name] = p

    add(cls.DESCRIPTOR.file)
    return files


def proto_diff(ours, theirs):
    lines = list(difflib.unified_diff(str(theirs).splitlines(), str(ours).splitlines(),
                                      "foxglove_schemas_protobuf", "recording", lineterm="", n=1))
    shown = "\n".join(lines[:40])
    more = f"\n    ... {len(lines) - 40} more diff lines" if len(lines) > 40 else ""
    return "\n    " + shown.replace("\n", "\n    ") + more


def check_protobuf_schema(topic, schema):
    """The class to decode `topic` with, once its schema is shown to be Foxglove's."""
    if schema is None:
        fail(f"{topic}: protobuf channel without a schema")
    if schema.encoding != "protobuf":
        fail(f"{topic}: message encoding protobuf but schema encoding {schema.encoding!r}")
    m = re.fullmatch(r"foxglove\.([A-Za-z][A-Za-z0-9]*)", schema.name)
    if not m:
        fail(f"{topic}: schema name {schema.name!r} is not foxglove.<Type>")
    type_name = m.group(1)
    allowed = EXPECTED_TYPES.get(topic)
    if allowed is not None and type_name not in allowed:
        fail(f"{topic}: carries {schema.name}, expected one of "
             f"{', '.join('foxglove.' + t for t in sorted(allowed))}")
    cls = shipped_class(type_name)
    if cls is None:
        fail(f"{topic}: foxglove_schemas_protobuf has no class for {schema.name}")
    if cls.DESCRIPTOR.full_name != schema.name:
        fail(f"{topic}: shipped class is {cls.DESCRIPTOR.full_name}, schema says {schema.name}")

    try:
        fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    except Exception as e:
        fail(f"{topic}: schema {schema.name} data is not a FileDescriptorSet: {e}")
    ours = OrderedDict()
    for fd in fds.file:
        if fd.name in ours:
            fail(f"{topic}: schema {schema.name} holds {fd.name} twice")
        ours[fd.name] = fd
    theirs = shipped_files(cls)

    # The same files: the type's own file and exactly what it imports.
    if set(ours) != set(theirs):
        missing = sorted(set(theirs) - set(ours))
        extra = sorted(set(ours) - set(theirs))
        fail(f"{topic}: schema {schema.name} files differ from Foxglove's: "
             f"missing {missing}, extra {extra}")
    # File by file, the descriptors Foxglove ships.
    for name, fd in ours.items():
        a, b = normalized(fd), normalized(theirs[name])
        if a != b:
            fail(f"{topic}: schema {schema.name}: {name} is not the one Foxglove ships:"
                 + proto_diff(a, b))
    # And the set stands on its own: a fresh pool builds it and finds the type.
    pool = descriptor_pool.DescriptorPool()
    added = set()

    def add(name, chain=()):
        if name in added:
            return
        if name in chain:
            fail(f"{topic}: schema {schema.name}: import cycle through {name}")
        for dep in ours[name].dependency:
            if dep not in ours:
                fail(f"{topic}: schema {schema.name}: {name} imports {dep}, not in the set")
            add(dep, chain + (name,))
        pool.Add(ours[name])
        added.add(name)

    try:
        for name in ours:
            add(name)
        found = pool.FindMessageTypeByName(schema.name)
    except Failure:
        raise
    except Exception as e:
        fail(f"{topic}: schema {schema.name} does not build on its own: {e}")
    if found.file.name != cls.DESCRIPTOR.file.name:
        fail(f"{topic}: {schema.name} is defined in {found.file.name}, "
             f"Foxglove defines it in {cls.DESCRIPTOR.file.name}")
    return cls


def is_repeated(fd):
    """protobuf >= 5.28 has is_repeated; older releases only the label."""
    flag = getattr(fd, "is_repeated", None)
    return flag if flag is not None else fd.label == fd.LABEL_REPEATED


def unknown_fields(msg, path="message"):
    """The path of the first (sub)message with fields its schema does not have."""
    if len(UnknownFieldSet(msg)):
        return path
    for fd, value in msg.ListFields():
        if fd.message_type is None:
            continue
        if fd.message_type.GetOptions().map_entry:
            items = value.values() if fd.message_type.fields_by_name["value"].message_type \
                else []
            for i, v in enumerate(items):
                p = unknown_fields(v, f"{path}.{fd.name}[{i}]")
                if p:
                    return p
        elif is_repeated(fd):
            for i, v in enumerate(value):
                p = unknown_fields(v, f"{path}.{fd.name}[{i}]")
                if p:
                    return p
        else:
            p = unknown_fields(value, f"{path}.{fd.name}")
            if p:
                return p
    return None


# ---------------------------------------------------------------- protobuf messages

def finite(*xs):
    return all(math.isfinite(x) for x in xs)


def check_compressed_image(msg, ctx):
    if msg.format != "jpeg":
        fail(f"{ctx}: format {msg.format!r}, expected 'jpeg'")
    if msg.data[:2] != b"\xff\xd8":
        fail(f"{ctx}: data does not start with the JPEG SOI marker FF D8 "
             f"(starts {msg.data[:4].hex()}, {len(msg.data)} bytes)")
    if msg.data[-2:] != b"\xff\xd9":
        fail(f"{ctx}: data does not end with the JPEG EOI marker FF D9")
    if not msg.frame_id:
        fail(f"{ctx}: empty frame_id")


def check_raw_image(msg, ctx):
    bpp = BYTES_PER_PIXEL.get(msg.encoding)
    if bpp is None:
        fail(f"{ctx}: unknown encoding {msg.encoding!r}")
    if msg.width == 0 or msg.height == 0:
        fail(f"{ctx}: empty image {msg.width}x{msg.height}")
    if msg.step < msg.width * bpp:
        fail(f"{ctx}: step {msg.step} < width {msg.width} * {bpp} bytes ({msg.encoding})")
    if msg.step * msg.height > len(msg.data):
        fail(f"{ctx}: step {msg.step} * height {msg.height} = {msg.step * msg.height} "
             f"> {len(msg.data)} data bytes")
    if not msg.frame_id:
        fail(f"{ctx}: empty frame_id")


def check_frame_transforms(msg, ctx):
    if not msg.transforms:
        fail(f"{ctx}: no transforms")
    for i, t in enumerate(msg.transforms):
        where = f"{ctx} transform {i} ({t.parent_frame_id} -> {t.child_frame_id})"
        for frame in (t.parent_frame_id, t.child_frame_id):
            if frame not in TF_FRAMES:
                fail(f"{where}: frame {frame!r} not among {sorted(TF_FRAMES)}")
        if t.parent_frame_id == t.child_frame_id:
            fail(f"{where}: a frame is its own parent")
        if not (t.HasField("translation") and t.HasField("rotation")):
            fail(f"{where}: translation or rotation missing")
        tr, q = t.translation, t.rotation
        if not finite(tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w):
            fail(f"{where}: non-finite translation {tr.x, tr.y, tr.z} or rotation "
                 f"{q.x, q.y, q.z, q.w}")
        norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
        if abs(norm - 1.0) > 1e-3:
            fail(f"{where}: rotation is not a unit quaternion (norm {norm})")


def check_scene_update(msg, ctx):
    for i, e in enumerate(msg.entities):
        if not e.frame_id:
            fail(f"{ctx}: entity {i} ({e.id!r}) has no frame_id")
        if not e.id:
            fail(f"{ctx}: entity {i} has no id")
        for kind in ("cubes", "spheres", "lines", "arrows", "cylinders", "texts",
                     "triangles", "models"):
            for j, prim in enumerate(getattr(e, kind)):
                p = prim.pose.position if prim.HasField("pose") else None
                if p is not None and not finite(p.x, p.y, p.z):
                    fail(f"{ctx}: entity {e.id!r} {kind}[{j}] at a non-finite position")
                for pt in getattr(prim, "points", ()):
                    if not finite(pt.x, pt.y, pt.z):
                        fail(f"{ctx}: entity {e.id!r} {kind}[{j}] has a non-finite point")


def check_log(msg, ctx):
    if not msg.message:
        fail(f"{ctx}: empty log message")
    if msg.level not in (1, 2, 3, 4, 5):
        fail(f"{ctx}: log level {msg.level} (expected DEBUG..FATAL, 1..5)")


SANITY = {
    "CompressedImage": check_compressed_image,
    "RawImage": check_raw_image,
    "FrameTransforms": check_frame_transforms,
    "SceneUpdate": check_scene_update,
    "Log": check_log,
}


# ---------------------------------------------------------------- JSON

def reject_constant(name):
    raise ValueError(f"{name} is not JSON")


def json_loads(data):
    return json.loads(data, parse_constant=reject_constant)


def resolve(schema, root):
    """A `$ref` into the root document's $defs/definitions, followed."""
    seen = 0
    while isinstance(schema, dict) and "$ref" in schema:
        ref = schema["$ref"]
        m = re.fullmatch(r"#/(\$defs|definitions)/(.+)", ref)
        if not m or m.group(2) not in root.get(m.group(1), {}):
            fail(f"unresolvable $ref {ref!r}")
        schema = root[m.group(1)][m.group(2)]
        seen += 1
        if seen > 64:
            fail(f"$ref loop at {ref!r}")
    return schema


TYPE_CHECKS = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool),
    "null": lambda v: v is None,
    "integer": lambda v: (isinstance(v, int) and not isinstance(v, bool))
    or (isinstance(v, float) and v.is_integer()),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
}
CHECKED = {"type", "properties", "items", "minItems", "maxItems", "required", "enum",
           "const", "additionalProperties", "minimum", "maximum", "$ref"}


def check_schema_doc(doc, root, path="schema"):
    """Every assertion keyword of the schema is one this reader checks."""
    doc = resolve(doc, root)
    if isinstance(doc, bool):
        return
    if not isinstance(doc, dict):
        fail(f"{path} is not a schema object")
    for k in doc:
        if k not in CHECKED and k not in ANNOTATIONS:
            fail(f"{path} uses `{k}`, which this reader does not check")
    types = doc.get("type", [])
    for t in types if isinstance(types, list) else [types]:
        if t not in TYPE_CHECKS:
            fail(f"{path}: unknown type {t!r}")
    for name, sub in doc.get("properties", {}).items():
        check_schema_doc(sub, root, f"{path}.properties.{name}")
    if isinstance(doc.get("items"), (dict, bool)):
        check_schema_doc(doc["items"], root, f"{path}.items")
    elif "items" in doc:
        fail(f"{path}.items is not a schema")
    if isinstance(doc.get("additionalProperties"), dict):
        check_schema_doc(doc["additionalProperties"], root, f"{path}.additionalProperties")
    for name, sub in root.get("$defs", {}).items() if path == "schema" else ():
        check_schema_doc(sub, root, f"schema.$defs.{name}")


def validate(value, schema, root, path):
    """The first place where `value` is not what `schema` says, as a message."""
    schema = resolve(schema, root)
    if schema is True or schema == {}:
        return None
    if schema is False:
        return f"{path}: not allowed"
    types = schema.get("type")
    if types is not None:
        types = types if isinstance(types, list) else [types]
        if not any(TYPE_CHECKS[t](value) for t in types):
            shown = "null (a NaN or infinity written as JSON null?)" if value is None \
                else f"{type(value).__name__} {json.dumps(value)[:60]}"
            return f"{path}: {shown}, schema type {'/'.join(types)}"
    if "enum" in schema and value not in schema["enum"]:
        return f"{path}: {value!r} not in {schema['enum']}"
    if "const" in schema and value != schema["const"]:
        return f"{path}: {value!r} != {schema['const']!r}"
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if "minimum" in schema and value < schema["minimum"]:
            return f"{path}: {value} < minimum {schema['minimum']}"
        if "maximum" in schema and value > schema["maximum"]:
            return f"{path}: {value} > maximum {schema['maximum']}"
    if isinstance(value, dict):
        props = schema.get("properties")
        extra_schema = schema.get("additionalProperties", None)
        for k in schema.get("required", []):
            if k not in value:
                return f"{path}: required key {k!r} missing"
        if props is not None:
            # Every key is one the schema names: the brief of this check (a plot or a
            # message path offered from the schema reaches every field).
            extra = sorted(set(value) - set(props))
            if extra and extra_schema in (None, False):
                return f"{path}: keys {extra} not among the schema's properties {sorted(props)}"
        for k, v in value.items():
            if props is not None and k in props:
                err = validate(v, props[k], root, f"{path}.{k}")
            elif isinstance(extra_schema, dict):
                err = validate(v, extra_schema, root, f"{path}.{k}")
            elif extra_schema is False:
                err = f"{path}: key {k!r} not allowed"
            else:
                err = None
            if err:
                return err
    if isinstance(value, list):
        if "minItems" in schema and len(value) < schema["minItems"]:
            return f"{path}: {len(value)} items < minItems {schema['minItems']}"
        if "maxItems" in schema and len(value) > schema["maxItems"]:
            return f"{path}: {len(value)} items > maxItems {schema['maxItems']}"
        if isinstance(schema.get("items"), (dict, bool)):
            for i, v in enumerate(value):
                err = validate(v, schema["items"], root, f"{path}[{i}]")
                if err:
                    return err
    return None


def check_json_schema(topic, channel, schema):
    if schema is None:
        fail(f"{topic}: JSON channel without a schema")
    if schema.encoding != "jsonschema":
        fail(f"{topic}: message encoding {channel.message_encoding!r} but schema encoding "
             f"{schema.encoding!r}, expected 'jsonschema'")
    try:
        doc = json_loads(schema.data)
    except ValueError as e:
        fail(f"{topic}: schema {schema.name} is not JSON: {e}")
    if not isinstance(doc, dict):
        fail(f"{topic}: schema {schema.name} is not a JSON object")
    if doc.get("type") != "object" or not isinstance(doc.get("properties"), dict):
        fail(f"{topic}: schema {schema.name} is not an object schema with properties")
    try:
        check_schema_doc(doc, doc)
    except Failure as e:
        fail(f"{topic}: schema {schema.name}: {e}")
    return doc


# ---------------------------------------------------------------- the file

class ChannelCheck:
    def __init__(self, channel, schema):
        self.topic = channel.topic
        self.schema_name = schema.name if schema else "(none)"
        self.count = 0
        self.frames = set()
        enc = channel.message_encoding
        if enc == "protobuf":
            self.kind = "protobuf"
            self.cls = check_protobuf_schema(self.topic, schema)
            self.sanity = SANITY.get(self.cls.DESCRIPTOR.name)
        elif enc == "json":
            self.kind = "json"
            self.doc = check_json_schema(self.topic, channel, schema)
        else:
            fail(f"{self.topic}: message encoding {enc!r} (expected protobuf or json)")

    def message(self, m):
        self.count += 1
        ctx = f"{self.topic} message {self.count} (log time {m.log_time} ns)"
        if self.kind == "protobuf":
            try:
                msg = self.cls.FromString(m.data)
            except Exception as e:
                fail(f"{ctx}: does not decode as {self.schema_name}: {e}")
            where = unknown_fields(msg)
            if where:
                fail(f"{ctx}: {where} has fields {self.schema_name} does not define")
            if self.sanity:
                self.sanity(msg, ctx)
            frame = getattr(msg, "frame_id", None)
            if frame:
                self.frames.add(frame)
            for e in getattr(msg, "entities", ()):
                self.frames.add(e.frame_id)
            for t in getattr(msg, "transforms", ()):
                self.frames.update((t.parent_frame_id, t.child_frame_id))
        else:
            try:
                value = json_loads(m.data)
            except ValueError as e:
                fail(f"{ctx}: not JSON: {e}: {bytes(m.data[:80])!r}")
            if not isinstance(value, dict):
                fail(f"{ctx}: not a JSON object: {bytes(m.data[:80])!r}")
            err = validate(value, self.doc, self.doc, "message")
            if err:
                fail(f"{ctx} ({self.schema_name}): {err}")


def check_metadata(reader):
    records = [m for m in reader.iter_metadata() if m.name == "landing"]
    if not records:
        fail("no metadata record named 'landing'")
    if len(records) > 1:
        fail(f"{len(records)} metadata records named 'landing'")
    meta = records[0].metadata
    missing = [k for k in METADATA_KEYS if k not in meta]
    if missing:
        fail(f"metadata 'landing' lacks {missing} (has {sorted(meta)})")
    for k in ("git_revision", "graph"):
        if not meta[k].strip():
            fail(f"metadata 'landing' has an empty {k}")
    return meta


def read(path, expect_raw_images):
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        try:
            summary = reader.get_summary()
        except Exception as e:
            fail(f"cannot read the summary ({type(e).__name__}: {e}): "
                 "a truncated or unfinished recording?")
        if summary is None:
            fail("no summary section: the recording was not finished")
        checks = {}
        total = 0
        last_time = {}
        for schema, channel, m in reader.iter_messages(log_time_order=False):
            c = checks.get(channel.id)
            if c is None:
                c = checks[channel.id] = ChannelCheck(channel, schema)
            c.message(m)
            if m.log_time < last_time.get(channel.id, 0):
                fail(f"{channel.topic}: log time goes back from {last_time[channel.id]} "
                     f"to {m.log_time} ns")
            last_time[channel.id] = m.log_time
            total += 1
        if total == 0:
            fail("the recording has no messages")
        # Channels declared but never written still get their schemas checked.
        for cid, channel in summary.channels.items():
            if cid not in checks:
                checks[cid] = ChannelCheck(channel, summary.schemas.get(channel.schema_id))
        stats = summary.statistics
        if stats is None:
            fail("the summary has no statistics")
        if stats.message_count != total:
            fail(f"statistics say {stats.message_count} messages, {total} were read")
        for cid, c in checks.items():
            said = stats.channel_message_counts.get(cid, 0)
            if said != c.count:
                fail(f"{c.topic}: statistics say {said} messages, {c.count} were read")
        meta = check_metadata(reader)

    topics = {c.topic: c for c in checks.values()}
    if len(topics) != len(checks):
        fail("two channels share a topic")
    camera = topics.get("/camera/frame")
    if expect_raw_images:
        if camera is None:
            fail("--expect-raw-images: no /camera/frame channel")
        if camera.schema_name != "foxglove.RawImage":
            fail(f"--expect-raw-images: /camera/frame carries {camera.schema_name}, "
                 "expected foxglove.RawImage")
        if camera.count == 0:
            fail("--expect-raw-images: /camera/frame has no messages")

    width = max(len(t) for t in topics)
    swidth = max(len(c.schema_name) for c in checks.values())
    for topic in sorted(topics):
        c = topics[topic]
        print(f"{topic:<{width}}  {c.schema_name:<{swidth}}  {c.count}")
    # Frames Foxglove's 3-D panel cannot place: named by a message, absent from /tf.
    tf = topics.get("/tf")
    if tf is not None:
        for topic in sorted(topics):
            c = topics[topic]
            off = sorted(c.frames - tf.frames - TF_FRAMES) if c is not tf else []
            if off:
                print(f"note: {topic} uses frame {', '.join(off)}, not in the /tf tree")
    print(f"metadata landing: git_revision {meta['git_revision']}, version {meta['version']}"
          + "".join(f", {k} {meta[k]}" for k in ("mode", "scenario", "seed") if k in meta))
    print(f"ok: {total} messages on {len(checks)} channels", flush=True)
    print("foxglove reader: 1 passed, 0 failed", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("file", help="the MCAP recording")
    parser.add_argument("--expect-raw-images", action="store_true",
                        help="/camera/frame must be foxglove.RawImage (recorded --raw-images)")
    args = parser.parse_args()
    try:
        read(args.file, args.expect_raw_images)
    except Failure as e:
        print(f"foxglove reader: FAILED: {args.file}: {e}", flush=True)
        sys.exit(1)
    except OSError as e:
        print(f"foxglove reader: FAILED: {e}", flush=True)
        sys.exit(1)
    except Exception as e:  # a file the mcap reader itself rejects (bad CRC, truncation)
        print(f"foxglove reader: FAILED: {args.file}: {type(e).__name__}: {e}", flush=True)
        sys.exit(1)


if __name__ == "__main__":
    main()
