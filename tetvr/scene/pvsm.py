"""The XML of a ParaView state file (``.pvsm``): its proxies and their properties, with
every number checked once, where it is read (:class:`StateProxy`). What a volume
rendering takes from them is :mod:`tetvr.scene.paraview`'s.

A bad number is a ``ValueError`` that names the state file, the proxy (its type and id),
the property, the value and what it must be: NaN or infinity, text, a fraction where a
count goes, or a count beyond a sane bound (``NumberOfTableValues`` of 1e9 would take
7 GiB) are refused before anything is built from them.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

__all__ = ["MAX_COMPONENT", "MAX_TABLE_VALUES", "MAX_VIEW_SIZE", "OPACITY_COLUMNS", "RGB_COLUMNS", "StateProxy",
           "node_rows", "parse_state"]

#: Bounds on what a state may ask for, checked where each number is read. A discretized
#: map's bands are two transfer-function rows each, each band's colour computed on the
#: map's curve (ParaView's default: 256 bands). 16384 bands are far more than 8-bit
#: colours tell apart, and build in about a second.
MAX_TABLE_VALUES = 1 << 14
#: Largest view size (pixels a side) and vector component taken from a state.
MAX_VIEW_SIZE = 1 << 16
MAX_COMPONENT = (1 << 16) - 1
#: Largest magnitude of a position, a scalar value or a time: beyond it the maps'
#: arithmetic (their span, a band's width) overflows float64.
_MAX_MAGNITUDE = 1e300
#: Most ``<Element>`` s of one property and their largest index.
_MAX_ELEMENTS = 1 << 20


class StateProxy:
    """One ``<Proxy>`` of a state; every number is checked here, as it is read, and a bad
    one is a ``ValueError`` naming the file, the proxy and the property."""

    def __init__(self, elem: ET.Element, path: str) -> None:
        self.path = path
        self.group = elem.get("group", "")
        self.type = elem.get("type", "")
        self.id = elem.get("id", "")
        self.name = ""  # its name in ParaView's pipeline browser (the state's ProxyCollection), if any
        self.props = {p.get("name", ""): p for p in elem.findall("Property")}

    def where(self, name: str) -> str:
        return f"{self.path}: {self.type or 'a proxy'} (id {self.id or '?'}) property {name}"

    def values(self, name: str) -> list[str]:
        prop = self.props.get(name)
        if prop is None:
            return []
        items = prop.findall("Element")
        if len(items) > _MAX_ELEMENTS:
            raise ValueError(f"{self.where(name)} holds {len(items)} values, more than the {_MAX_ELEMENTS} "
                             "tetvr reads; is the state damaged?")
        return [e.get("value", "") for e in sorted(items, key=lambda e: self._index(name, e))]

    def _index(self, name: str, elem: ET.Element) -> int:
        raw = elem.get("index", "0")
        try:
            index = int(raw)
        except ValueError:
            index = -1
        if not 0 <= index < _MAX_ELEMENTS:
            raise ValueError(f"{self.where(name)} has an <Element index={raw!r}>; an index is a whole number "
                             f"from 0 to {_MAX_ELEMENTS - 1}: is the state damaged?")
        return index

    def refs(self, name: str) -> list[str]:
        prop = self.props.get(name)
        return [] if prop is None else [p.get("value", "") for p in prop.findall("Proxy")]

    def floats(self, name: str, n: int | None = None, *, lo: float = -_MAX_MAGNITUDE,
               hi: float = _MAX_MAGNITUDE) -> list[float] | None:
        """The property's numbers, each finite and in ``[lo, hi]``; None if it has none."""
        vals = self.values(name)
        if not vals:
            return None
        out = [self._number(name, v, lo, hi) for v in vals]
        if n is not None and len(out) != n:
            raise ValueError(f"{self.where(name)} holds {len(out)} numbers, expected {n}")
        return out

    def _number(self, name: str, text: str, lo: float, hi: float) -> float:
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"{self.where(name)} holds {text!r}, not a number; fix or remove that value "
                             "(ParaView writes plain decimal numbers)") from None
        if not math.isfinite(value):
            raise ValueError(f"{self.where(name)} holds {text!r}; a state's numbers must be finite: fix or remove "
                             "that value")
        if not lo <= value <= hi:
            raise ValueError(f"{self.where(name)} holds {text!r}, outside [{lo:g}, {hi:g}]; fix that value")
        return value

    def number(self, name: str, default: float | None = None, **bounds: float) -> float | None:
        vals = self.floats(name, **bounds)
        return default if not vals else vals[0]

    def integer(self, name: str, default: int, lo: int, hi: int) -> int:
        """The property's first value as a whole number in ``[lo, hi]`` (``default`` if absent)."""
        vals = self.values(name)
        return default if not vals else self.whole(name, vals[0], lo, hi)

    def whole(self, name: str, text: str, lo: int, hi: int) -> int:
        value = self._number(name, text, -_MAX_MAGNITUDE, _MAX_MAGNITUDE)
        if value != int(value) or not lo <= value <= hi:
            raise ValueError(f"{self.where(name)} must be a whole number from {lo} to {hi}, got {text!r}; "
                             "fix that value")
        return int(value)

    def integers(self, name: str, n: int, lo: int, hi: int) -> list[int] | None:
        """The property's ``n`` values as whole numbers in ``[lo, hi]``; None if it has none."""
        vals = self.values(name)
        if vals and len(vals) != n:
            raise ValueError(f"{self.where(name)} holds {len(vals)} numbers, expected {n}")
        return [self.whole(name, v, lo, hi) for v in vals] or None

    def flag(self, name: str, default: bool = False) -> bool:
        vals = self.values(name)
        return default if not vals else bool(self.whole(name, vals[0], 0, 1))

    def text(self, name: str, default: str | None = None) -> str | None:
        vals = self.values(name)
        return vals[0] if vals else default

    def enum_text(self, name: str, table: dict[int, str]) -> str | None:
        """An enumeration's entry, by the names the state lists (else ``table``)."""
        if not self.values(name):
            return None
        raw = self.integer(name, 0, -(1 << 31), (1 << 31) - 1)
        prop = self.props[name]
        for entry in prop.iter("Entry"):
            if entry.get("value") == str(raw):
                return entry.get("text")
        return table.get(raw, str(raw))


def parse_state(path: str) -> tuple[str, dict[str, StateProxy]]:
    """The state's version and its proxies by id."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"{path}: not a ParaView state file (not valid XML: {exc})") from None
    sms = root if root.tag == "ServerManagerState" else root.find("ServerManagerState")
    if sms is None:
        raise ValueError(f"{path}: not a ParaView state file (no <ServerManagerState>, root is <{root.tag}>)")
    version = sms.get("version", "")
    proxies = {p.id: p for p in (StateProxy(e, path) for e in sms.findall("Proxy"))}
    for collection in sms.findall("ProxyCollection"):
        for item in collection.findall("Item"):
            proxy = proxies.get(item.get("id", ""))
            if proxy is not None and not proxy.name:
                proxy.name = item.get("name", "")
    return version, proxies


#: The columns of a colour map's and an opacity function's nodes, with their ranges.
RGB_COLUMNS = (("position", -_MAX_MAGNITUDE, _MAX_MAGNITUDE), ("red", 0.0, 1.0), ("green", 0.0, 1.0),
               ("blue", 0.0, 1.0))
OPACITY_COLUMNS = (("position", -_MAX_MAGNITUDE, _MAX_MAGNITUDE), ("opacity", 0.0, 1.0), ("midpoint", 0.0, 1.0),
                   ("sharpness", 0.0, 1.0))
Columns = tuple[tuple[str, float, float], ...]


def node_rows(proxy: StateProxy, name: str, columns: Columns) -> tuple[tuple[float, ...], ...]:
    """A map's nodes: groups of ``len(columns)`` numbers, each column in its range."""
    values = proxy.floats(name)
    width = len(columns)
    if not values or len(values) % width:
        raise ValueError(f"{proxy.where(name)} must hold groups of {width} numbers "
                         f"({', '.join(c[0] for c in columns)}), got {0 if not values else len(values)}")
    rows = tuple(tuple(values[i:i + width]) for i in range(0, len(values), width))
    for k, row in enumerate(rows):
        for (label, lo, hi), v in zip(columns, row):
            if not lo <= v <= hi:
                raise ValueError(f"{proxy.where(name)}: node {k}'s {label} is {v!r}, outside [{lo:g}, {hi:g}]; "
                                 "fix that value")
    return rows
