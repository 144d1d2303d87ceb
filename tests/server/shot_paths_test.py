#!/usr/bin/env python3
"""The Python client and the benchmarks upload/resolve the files a shot names from one list
(client/python/cloudbake_shot_paths.py): it must be the set of properties that
docs/shot.schema.json types as paths.

Usage: shot_paths_test.py SOURCE_ROOT
"""

import json
import os
import re
import sys

PATH_REF = "#/$defs/path"


def path_pointers(schema, node, pointer, out, depth=0):
    """Pointers ("*" for array elements) of every place below `node` whose schema is PATH_REF."""
    assert depth < 64, "schema recursion at " + pointer
    if not isinstance(node, dict):
        return  # true/false schemas name no type
    ref = node.get("$ref")
    if ref == PATH_REF:
        out.add(pointer)
        return
    if ref is not None:
        assert ref.startswith("#/"), "unexpected $ref " + ref
        target = schema
        for token in ref[2:].split("/"):
            target = target[token]
        path_pointers(schema, target, pointer, out, depth + 1)
    for key in ("allOf", "anyOf", "oneOf"):
        for alt in node.get(key, []):
            path_pointers(schema, alt, pointer, out, depth + 1)
    for key in ("if", "then", "else"):
        if key in node:
            path_pointers(schema, node[key], pointer, out, depth + 1)
    for key, sub in node.get("properties", {}).items():
        path_pointers(schema, sub, pointer + "/" + key, out, depth + 1)
    if "items" in node:
        path_pointers(schema, node["items"], pointer + "/*", out, depth + 1)


def main():
    root = sys.argv[1]
    sys.path.insert(0, os.path.join(root, "client", "python"))
    import cloudbake_shot_paths as sp

    with open(os.path.join(root, "docs", "shot.schema.json")) as f:
        schema = json.load(f)
    assert schema["$defs"]["path"]["type"] == "string", "paths are no longer " + PATH_REF
    from_schema = set()
    path_pointers(schema, schema, "", from_schema)
    listed = set(sp.PATH_POINTERS)
    assert len(listed) == len(sp.PATH_POINTERS), "duplicates in PATH_POINTERS"
    assert listed == from_schema, "PATH_POINTERS %s, schema %s" % (sorted(listed),
                                                                   sorted(from_schema))

    shot = {"volume": {"sequence": {"paths": ["f0.vdb", 7, "f1.vdb"]}, "vdb": {"path": "a.vdb"},
                       "mesh": {"path": "m.ply"}},
            "lighting": {"sky": {"map": "sky.exr"}}, "name": "not/a/path.vdb"}
    assert sp.referenced_paths(shot) == ["a.vdb", "m.ply", "f0.vdb", "f1.vdb", "sky.exr"]
    container, key = sp.path_slots(shot)[0]
    container[key] = "/abs/a.vdb"
    assert shot["volume"]["vdb"]["path"] == "/abs/a.vdb"
    for bad in ([1, 2], "shot", {"volume": []}, {"lighting": {"sky": "blue"}},
                {"volume": {"vdb": {"path": 3}, "sequence": {"paths": "x"}}}):
        assert sp.referenced_paths(bad) == [], bad
    # The Python client's copy of the server's limit on files per job (it checks it before
    # hashing any): read as text, since importing the client needs grpc.
    with open(os.path.join(root, "core", "job", "asset_limits.h")) as f:
        limit = re.search(r"kMaxJobAssets = (\d+);", f.read())
    with open(os.path.join(root, "client", "python", "cloudbake_client.py")) as f:
        py_limit = re.search(r"^MAX_JOB_ASSETS = (\d+)", f.read(), re.M)
    assert limit and py_limit and limit.group(1) == py_limit.group(1), "MAX_JOB_ASSETS differs"
    print("shot paths: %d pointers match docs/shot.schema.json" % len(listed))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
