#!/usr/bin/python3
"""nupmpc.v1 only grows: the API of proto/nupmpc/v1/*.proto against its committed baseline.

    proto_compat_check.py check SOURCE_DIR
    proto_compat_check.py update SOURCE_DIR

The baseline, proto/api_baseline/nupmpc_v1.txtpb, is the FileDescriptorSet protoc makes of
the tree, in text format (reviewable diffs) without source info. `check` compiles the tree
and compares element by element (messages, fields, enums, their values, services, RPCs,
files), by full name:

* breaking (exit status 1, one line per change): a removed file, message, enum, service or
  RPC; a removed field or enum value, unless it was retired, i.e. its number and its name
  are now both reserved (the number so that no later field reuses it on the wire, the
  name so that none reuses it in JSON and text format); a field or enum value renumbered;
  a field retyped (scalar, message or enum type, repeated/singular/proto3 optional/map, its
  oneof), or its JSON name changed; an RPC's request or response type or streaming
  changed; a package or syntax changed; a reserved number or name no longer reserved;
* compatible: everything added, and retirements. These too make `check` fail until
  `update` has written them into the baseline, so that the baseline moves in the same
  commit as the API and its diff shows the API change in review. So does any other
  difference in the baseline's text (declaration order, options): the baseline is always
  exactly what `update` writes.

`update` rewrites the baseline from the tree, and refuses to when the change is breaking:
a breaking change belongs in a new package (nupmpc.v2), not in v1.

Debian's interpreter (/usr/bin/python3): protobuf comes from python3-protobuf.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import tempfile
from typing import Any, Iterable

from google.protobuf import descriptor_pb2, text_format  # type: ignore[import]

PROTO_ROOT = "proto"
API_DIR = "nupmpc/v1"
BASELINE = os.path.join("proto", "api_baseline", "nupmpc_v1.txtpb")
PROTOC = "/usr/bin/protoc"
HEADER = (
    "# proto-file: google/protobuf/descriptor.proto\n"
    "# proto-message: FileDescriptorSet\n"
    "# The nupmpc.v1 API that later versions must stay compatible with (README.md here).\n"
    "# Written by tests/build/proto_compat_check.py update; do not edit by hand.\n"
)

FieldProto = descriptor_pb2.FieldDescriptorProto
Message = Any  # a protobuf message; Debian's python3-protobuf has no type stubs
Ranges = list[tuple[int, int]]  # [start, end), end exclusive


@dataclasses.dataclass
class Api:
    """The elements of a FileDescriptorSet, by full name (package.Outer.Inner)."""

    files: dict[str, Message] = dataclasses.field(default_factory=dict)
    messages: dict[str, Message] = dataclasses.field(default_factory=dict)
    enums: dict[str, Message] = dataclasses.field(default_factory=dict)
    services: dict[str, Message] = dataclasses.field(default_factory=dict)
    # The synthetic entry messages of map fields: part of their field's type, not messages.
    map_entries: dict[str, Message] = dataclasses.field(default_factory=dict)


def index_api(file_set: Message) -> Api:
    api = Api()

    def add_messages(scope: str, messages: Iterable[Message]) -> None:
        for message in messages:
            name = f"{scope}.{message.name}" if scope else message.name
            if message.options.map_entry:
                api.map_entries[name] = message
                continue
            api.messages[name] = message
            add_enums(name, message.enum_type)
            add_messages(name, message.nested_type)

    def add_enums(scope: str, enums: Iterable[Message]) -> None:
        for enum in enums:
            api.enums[f"{scope}.{enum.name}" if scope else enum.name] = enum

    for file in file_set.file:
        api.files[file.name] = file
        package = str(file.package)
        add_messages(package, file.message_type)
        add_enums(package, file.enum_type)
        for service in file.service:
            api.services[f"{package}.{service.name}" if package else service.name] = service
    return api


def type_of(field: Message, api: Api) -> str:
    """How a field is declared, e.g. `repeated double`, `optional uint32`, `map<string, uint64>`."""
    if field.type in (FieldProto.TYPE_MESSAGE, FieldProto.TYPE_ENUM):
        base = str(field.type_name).lstrip(".")
    else:
        base = FieldProto.Type.Name(field.type).removeprefix("TYPE_").lower()
    if field.label == FieldProto.LABEL_REPEATED:
        entry = api.map_entries.get(base)
        if entry is not None:
            key, value = entry.field
            return f"map<{type_of(key, api)}, {type_of(value, api)}>"
        return f"repeated {base}"
    if field.label == FieldProto.LABEL_REQUIRED:
        return f"required {base}"
    return f"optional {base}" if field.proto3_optional else base


def oneof_of(field: Message, message: Message) -> str:
    """The real oneof a field belongs to ("" for none; proto3 optional's own oneof is none)."""
    if not field.HasField("oneof_index") or field.proto3_optional:
        return ""
    return str(message.oneof_decl[field.oneof_index].name)


def covers(ranges: Ranges, start: int, end: int) -> bool:
    """Whether the union of `ranges` holds every number of [start, end)."""
    for low, high in sorted(ranges):
        if low > start:
            return False
        start = max(start, high)
        if start >= end:
            return True
    return start >= end


def show_range(start: int, end: int) -> str:
    return str(start) if end == start + 1 else f"{start} to {end - 1}"


@dataclasses.dataclass
class Comparison:
    breaking: list[str] = dataclasses.field(default_factory=list)
    compatible: list[str] = dataclasses.field(default_factory=list)


def compare_reserved(where: str, old: Message, new: Message, inclusive_end: bool,
                     result: Comparison) -> tuple[Ranges, set[str]]:
    """Reserved numbers and names of old and new message (or enum); returns the new ones."""
    def ranges_of(element: Message) -> Ranges:
        return [(r.start, r.end + 1 if inclusive_end else r.end) for r in element.reserved_range]

    old_ranges, new_ranges = ranges_of(old), ranges_of(new)
    for start, end in old_ranges:
        if not covers(new_ranges, start, end):
            result.breaking.append(f"{where}: reserved number {show_range(start, end)} no longer reserved")
    for start, end in new_ranges:
        if not covers(old_ranges, start, end):
            result.compatible.append(f"{where}: number {show_range(start, end)} reserved")
    old_names, new_names = set(old.reserved_name), set(new.reserved_name)
    for name in sorted(old_names - new_names):
        result.breaking.append(f"{where}: reserved name {name} no longer reserved")
    for name in sorted(new_names - old_names):
        result.compatible.append(f"{where}: name {name} reserved")
    return new_ranges, new_names


def compare_message(name: str, old: Message, new: Message, old_api: Api, new_api: Api,
                    result: Comparison) -> None:
    reserved_numbers, reserved_names = compare_reserved(name, old, new, False, result)
    new_fields = {f.name: f for f in new.field}
    new_by_number = {f.number: f for f in new.field}
    for old_field in old.field:
        where = f"{name}.{old_field.name}"
        number = old_field.number
        new_field = new_fields.get(old_field.name)
        if new_field is None:
            if covers(reserved_numbers, number, number + 1) and old_field.name in reserved_names:
                result.compatible.append(f"{where}: field {number} retired (number and name reserved)")
                continue
            successor = new_by_number.get(number)
            now = f", number {number} now belongs to {successor.name}" if successor else ""
            result.breaking.append(f"{where}: field {number} removed{now} "
                                   "(retire a field by reserving its number and its name)")
            continue
        if new_field.number != number:
            result.breaking.append(f"{where}: field renumbered from {number} to {new_field.number}")
        old_type, new_type = type_of(old_field, old_api), type_of(new_field, new_api)
        if old_type != new_type:
            result.breaking.append(f"{where}: field {number} retyped from {old_type} to {new_type}")
        old_oneof, new_oneof = oneof_of(old_field, old), oneof_of(new_field, new)
        if old_oneof != new_oneof:
            result.breaking.append(f"{where}: field {number} moved from "
                                   f"{'oneof ' + old_oneof if old_oneof else 'no oneof'} to "
                                   f"{'oneof ' + new_oneof if new_oneof else 'no oneof'}")
        if old_field.json_name != new_field.json_name:
            result.breaking.append(f"{where}: field {number} JSON name changed from "
                                   f"{old_field.json_name} to {new_field.json_name}")
    old_names = {f.name for f in old.field}
    for new_field in new.field:
        if new_field.name not in old_names:
            result.compatible.append(f"{name}.{new_field.name}: field {new_field.number} added "
                                     f"({type_of(new_field, new_api)})")


def compare_enum(name: str, old: Message, new: Message, result: Comparison) -> None:
    reserved_numbers, reserved_names = compare_reserved(name, old, new, True, result)
    new_values = {v.name: v for v in new.value}
    for old_value in old.value:
        where = f"{name}.{old_value.name}"
        number = old_value.number
        new_value = new_values.get(old_value.name)
        if new_value is None:
            if covers(reserved_numbers, number, number + 1) and old_value.name in reserved_names:
                result.compatible.append(f"{where}: enum value {number} retired (number and name reserved)")
            else:
                result.breaking.append(f"{where}: enum value {number} removed "
                                       "(retire a value by reserving its number and its name)")
        elif new_value.number != number:
            result.breaking.append(f"{where}: enum value renumbered from {number} to {new_value.number}")
    old_names = {v.name for v in old.value}
    for new_value in new.value:
        if new_value.name not in old_names:
            result.compatible.append(f"{name}.{new_value.name}: enum value {new_value.number} added")


def compare_service(name: str, old: Message, new: Message, result: Comparison) -> None:
    def side(streaming: bool, type_name: str) -> str:
        return ("stream " if streaming else "") + type_name.lstrip(".")

    new_methods = {m.name: m for m in new.method}
    for old_method in old.method:
        where = f"{name}.{old_method.name}"
        new_method = new_methods.get(old_method.name)
        if new_method is None:
            result.breaking.append(f"{where}: RPC removed")
            continue
        for what, streaming, type_name in (("request", "client_streaming", "input_type"),
                                           ("response", "server_streaming", "output_type")):
            before = side(getattr(old_method, streaming), getattr(old_method, type_name))
            after = side(getattr(new_method, streaming), getattr(new_method, type_name))
            if before != after:
                result.breaking.append(f"{where}: RPC {what} changed from {before} to {after}")
    old_names = {m.name for m in old.method}
    for new_method in new.method:
        if new_method.name not in old_names:
            result.compatible.append(f"{name}.{new_method.name}: RPC added")


def compare(old_set: Message, new_set: Message) -> Comparison:
    old, new = index_api(old_set), index_api(new_set)
    result = Comparison()
    for name, old_file in old.files.items():
        new_file = new.files.get(name)
        if new_file is None:
            result.breaking.append(f"{name}: file removed or renamed")
            continue
        for attribute in ("package", "syntax"):
            before, after = getattr(old_file, attribute), getattr(new_file, attribute)
            if before != after:
                result.breaking.append(f"{name}: {attribute} changed from {before!r} to {after!r}")
    result.compatible += [f"{name}: file added" for name in new.files if name not in old.files]

    kinds = (("message", old.messages, new.messages), ("enum", old.enums, new.enums),
             ("service", old.services, new.services))
    for kind, old_elements, new_elements in kinds:
        for name, old_element in old_elements.items():
            new_element = new_elements.get(name)
            if new_element is None:
                result.breaking.append(f"{name}: {kind} removed")
            elif kind == "message":
                compare_message(name, old_element, new_element, old, new, result)
            elif kind == "enum":
                compare_enum(name, old_element, new_element, result)
            else:
                compare_service(name, old_element, new_element, result)
        result.compatible += [f"{name}: {kind} added" for name in new_elements if name not in old_elements]
    return result


def compile_api(source_dir: str) -> Message:
    """The FileDescriptorSet of the tree's API, without source info, files in name order."""
    proto_root = os.path.join(source_dir, PROTO_ROOT)
    api_dir = os.path.join(proto_root, API_DIR)
    files = sorted(f"{API_DIR}/{name}" for name in os.listdir(api_dir) if name.endswith(".proto"))
    with tempfile.TemporaryDirectory() as temp:
        out = os.path.join(temp, "api.pb")
        # protoc finds the google/protobuf/*.proto it ships with by itself.
        run = subprocess.run([PROTOC, f"--proto_path={proto_root}", f"--descriptor_set_out={out}", *files],
                             capture_output=True, text=True)
        if run.returncode != 0:
            print(f"protoc failed on {api_dir}:\n{run.stderr}", file=sys.stderr)
            sys.exit(2)
        file_set = descriptor_pb2.FileDescriptorSet()
        with open(out, "rb") as f:
            file_set.ParseFromString(f.read())
    for file in file_set.file:
        file.ClearField("source_code_info")
    file_set.file.sort(key=lambda file: str(file.name))
    return file_set


def render(file_set: Message) -> str:
    return HEADER + str(text_format.MessageToString(file_set))


def count(file_set: Message) -> str:
    api = index_api(file_set)
    fields = sum(len(message.field) for message in api.messages.values())
    rpcs = sum(len(service.method) for service in api.services.values())
    return f"{len(api.messages)} messages, {fields} fields, {len(api.enums)} enums, {rpcs} RPCs"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("mode", choices=["check", "update"])
    parser.add_argument("source_dir")
    args = parser.parse_args()

    current = compile_api(args.source_dir)
    packages = ", ".join(sorted({str(file.package) for file in current.file}))
    baseline_path = os.path.join(args.source_dir, BASELINE)
    baseline_text = None
    result = Comparison()
    if os.path.exists(baseline_path):
        with open(baseline_path, encoding="utf-8") as f:
            baseline_text = f.read()
        baseline = text_format.Parse(baseline_text, descriptor_pb2.FileDescriptorSet())
        result = compare(baseline, current)

    if result.breaking:
        print(f"{packages}: {len(result.breaking)} breaking changes against {BASELINE}:")
        for line in result.breaking:
            print(f"  {line}")
        print(f"{packages} is promised stable: add, never remove, renumber or retype. To retire a field "
              "or enum value, reserve its number and its name.")
        if args.mode == "update":
            print("Not updating the baseline: a breaking change belongs in a new package version.")
        return 1

    text = render(current)
    if args.mode == "update":
        if text == baseline_text:
            print(f"{BASELINE} is up to date: {count(current)}")
            return 0
        os.makedirs(os.path.dirname(baseline_path), exist_ok=True)
        with open(baseline_path, "w", encoding="utf-8") as f:
            f.write(text)
        for line in result.compatible:
            print(f"  {line}")
        print(f"wrote {BASELINE}: {count(current)}; commit it with the change of the API")
        return 0

    if baseline_text is None:
        print(f"no baseline at {BASELINE}: run `tests/build/proto_compat_check.py update .`")
        return 1
    if text != baseline_text:
        if result.compatible:
            print(f"{packages} compatible with the baseline, but {len(result.compatible)} changes are not "
                  "yet in it:")
            for line in result.compatible:
                print(f"  {line}")
        else:
            print(f"{packages} compatible with the baseline, but the baseline's text differs from the "
                  "tree's in declaration order or options.")
        print(f"Run `tests/build/proto_compat_check.py update {args.source_dir}` and commit "
              f"{BASELINE} with the change.")
        return 1
    print(f"{packages} compatible with the baseline: {count(current)}; the baseline is up to date")
    return 0


if __name__ == "__main__":
    sys.exit(main())
