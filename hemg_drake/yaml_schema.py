"""Raw YAML checked against a typed schema, before Drake's typed loader reads it.

``yaml_load_typed`` stops at the first mismatch with a C++ message that names neither the
key nor the file. :func:`check_types` walks the raw data (``yaml.safe_load`` output) over a
dataclass or Drake config struct and names the key path of the first problem, in one line;
scenarios (:mod:`hemg_drake.scenario`) and sweep files (:mod:`hemg_drake.sweep`) share it.
:func:`override_data` turns a ``--set key.path=value`` into the data of one more layer for
``yaml_load_typed(defaults=...)``; :func:`parse_yaml` reads YAML text with one-line errors.
"""

import dataclasses as dc
import re
import typing

import yaml


def first_line(error):
    """The first line of an exception's message (its type's name if it has none)."""
    return (str(error).strip().splitlines() or [type(error).__name__])[0]


def schema_fields(schema):
    """(name, type) of a dataclass's or a Drake config struct's fields."""
    if dc.is_dataclass(schema):
        hints = typing.get_type_hints(schema)
        return {f.name: hints[f.name] for f in dc.fields(schema)}
    return {f.name: f.type for f in schema.__fields__}


_TYPE_NAMES = {float: "a number", int: "an integer", bool: "true or false", str: "a string"}


# Numbers in scientific notation that YAML 1.1 (PyYAML, Drake's loader) reads as text:
# 2e-3 (no dot) and 3.0e4 (no sign in the exponent). Read where a number is expected.
_SCIENTIFIC = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+")


def check_types(value, schema, key=""):
    """Check raw YAML data against ``schema``, naming the key path of the first mismatch.

    ``schema``: a dataclass or Drake config struct, ``list[X]``, ``dict[str, X]``,
    ``Optional[X]``, float, int, bool or str. Returns the value, with numbers written as
    ``2e-3`` or ``3.0e4`` read as numbers (lists and mappings are updated in place).
    Raises ValueError naming the key.
    """
    where = f"key '{key}'" if key else "the top level"
    origin, args = typing.get_origin(schema), typing.get_args(schema)
    if origin is typing.Union:  # Optional[X]
        if value is not None:
            return check_types(value, next(a for a in args if a is not type(None)), key)
    elif origin is list or getattr(schema, "__name__", None) == "ndarray":
        # An np.ndarray field of a Drake struct (Rgba's rgba) reads a list of numbers.
        args = args or (float,)
        if not isinstance(value, list):
            raise ValueError(f"{where} must be a list, got {value!r}")
        for i, item in enumerate(value):
            value[i] = check_types(item, args[0], f"{key}[{i}]")
    elif origin is dict:
        if not isinstance(value, dict):
            raise ValueError(f"{where} must be a mapping, got {value!r}")
        for name, item in value.items():
            value[name] = check_types(item, args[1], f"{key}.{name}")
    elif schema in (float, int, bool, str):
        if schema is float and isinstance(value, str) and _SCIENTIFIC.fullmatch(value.strip()):
            value = float(value)
        ok = {
            float: isinstance(value, (int, float)) and not isinstance(value, bool),
            int: isinstance(value, int) and not isinstance(value, bool),
            bool: isinstance(value, bool),
            str: isinstance(value, str),
        }[schema]
        if not ok:
            raise ValueError(f"{where} must be {_TYPE_NAMES[schema]}, got {value!r}")
    else:
        if not isinstance(value, dict):
            raise ValueError(
                f"{where} must be a mapping of {schema.__name__}'s fields, got {value!r}"
            )
        fields = schema_fields(schema)
        unknown = sorted(set(value) - set(fields))
        if unknown:
            prefix = f"{key}." if key else ""
            raise ValueError(
                f"unknown key(s) {[prefix + str(u) for u in unknown]}; "
                f"{schema.__name__} has {sorted(fields)}"
            )
        for name, item in value.items():
            value[name] = check_types(item, fields[name], f"{key}.{name}" if key else name)
    return value


def parse_yaml(text, source):
    """The data of YAML ``text``; malformed YAML, or a key given twice in one mapping (YAML
    loaders keep the last without a word), is a one-line ValueError naming ``source`` (with
    the line and column, or the key path and its lines)."""
    if not text.strip():
        return None
    try:
        twice = _key_given_twice(yaml.compose(text, Loader=yaml.SafeLoader))
        if twice is not None:
            key, first, second = twice
            lines = f"on line {first}" if first == second else f"at lines {first} and {second}"
            raise ValueError(f"{source}: key '{key}' is given twice, {lines}: give it once")
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(error, "problem", None) or first_line(error)
        raise ValueError(f"{source}: malformed YAML{where}: {problem}") from None


def _key_given_twice(node, path="", seen=None):
    """(key path, first line, second line) of the first key that a mapping under ``node`` (a
    composed YAML node) holds twice, else None. Merge keys (``<<``) may be overridden."""
    seen = set() if seen is None else seen
    if node is None or id(node) in seen:  # an alias is checked where its anchor is
        return None
    seen.add(id(node))
    if isinstance(node, yaml.MappingNode):
        lines = {}
        for key_node, value_node in node.value:
            name = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
            child = f"{path}.{name}" if path else str(name)
            if name is not None and key_node.tag != "tag:yaml.org,2002:merge":
                line = key_node.start_mark.line + 1
                if name in lines:
                    return child, lines[name], line
                lines[name] = line
            found = _key_given_twice(value_node, child, seen)
            if found is not None:
                return found
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            found = _key_given_twice(item, f"{path}[{i}]", seen)
            if found is not None:
                return found
    return None


def override_data(override, schema):
    """``"dotted.key=value"`` (value in YAML syntax) as nested data ``{dotted: {key: value}}``.

    The dotted key's sections are looked up in ``schema`` (a dataclass or Drake config struct)
    so that a key that holds a value is refused as a section; an unknown name is left for
    :func:`check_types` to name. Raises ValueError (one line) for a malformed override.
    """
    key, equals, value_text = str(override).partition("=")
    key = key.strip()
    if not equals or not key or any(not part for part in key.split(".")):
        raise ValueError("an override must read key=value, e.g. emg.k_max=150")
    if not value_text.strip():
        raise ValueError(f"an override needs a value after '=', e.g. {key}=...")
    value = parse_yaml(value_text, "the value")
    *parents, leaf = key.split(".")
    for depth, name in enumerate(parents):
        fields = schema_fields(schema)
        if name not in fields:
            break
        schema = _section(fields[name])
        if schema is None:
            path = ".".join(parents[: depth + 1])
            raise ValueError(f"key '{path}' holds a value, not a section: cannot set '{key}'")
    data = {leaf: value}
    for name in reversed(parents):
        data = {name: data}
    return data


def _section(schema):
    """``schema`` (Optional[X] unwrapped) if it is a dataclass or a config struct, else None."""
    if typing.get_origin(schema) is typing.Union:
        schema = next(a for a in typing.get_args(schema) if a is not type(None))
    return schema if dc.is_dataclass(schema) or hasattr(schema, "__fields__") else None
