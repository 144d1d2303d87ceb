"""Where a shot (format v1) names files: the JSON pointers of the properties that
docs/shot.schema.json types as "#/$defs/path".

The Python copy of client/shot_paths.h; tests/server/shot_paths_test.py checks it against the
schema. Plain Python (no gRPC), so scripts such as bench/trade_bench.py can import it too.
"""

# "*" stands for every element of an array.
PATH_POINTERS = (
    "/volume/vdb/path",
    "/volume/mesh/path",
    "/volume/sequence/paths/*",
    "/lighting/sky/map",
)


def path_slots(shot):
    """(container, key) of every path string in a parsed shot, in PATH_POINTERS order, so that
    callers can read or rewrite container[key]. Absent keys and values of other types are
    skipped: the parser, not this, reports what is malformed."""
    slots = []
    for pointer in PATH_POINTERS:
        _collect(shot, pointer.split("/")[1:], slots)
    return slots


def _collect(node, tokens, slots):
    token, rest = tokens[0], tokens[1:]
    if token == "*":
        children = list(enumerate(node)) if isinstance(node, list) else []
    else:
        children = [(token, node[token])] if isinstance(node, dict) and token in node else []
    for key, child in children:
        if rest:
            _collect(child, rest, slots)
        elif isinstance(child, str):
            slots.append((node, key))


def referenced_paths(shot):
    """Paths a shot (format v1, parsed JSON) names: the only keys that hold files."""
    return [container[key] for container, key in path_slots(shot)]
