"""OpenSim setup files (``<OpenSimDocument><InverseDynamicsTool ...>``), read property by property.

A setup file names a tool (its root's first element) and holds that tool's
properties: text values (``<time_range> 0.4 1.6 </time_range>``), nested
objects (``<GenericModelMaker>``) and sets (``<MeasurementSet><objects>
<Measurement name=...>``).  :class:`SetupNode` hands out the values a tool
runner reads, converted and checked, and :meth:`SetupNode.finish` refuses by
name every property the runner did not read that carries a value: a setup is
never run with a property silently ignored.  A property left empty (OpenSim
writes every property, most at their empty default) is no instruction and
passes.

Paths are resolved as OpenSim's tools resolve them: relative to the setup
file's folder.  A missing file is refused with the path it resolved to.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from ..errors import PinmskError

__all__ = ["SetupError", "SetupFile", "SetupNode", "parse_xml", "read_setup"]


class SetupError(PinmskError):
    """A setup file that cannot be run as written (named property, element and file)."""


_TRUE = {"true", "1", "yes", "on"}
_FALSE = {"false", "0", "no", "off"}


class SetupNode:
    """One element of a setup file (the tool, or an object inside it).

    ``where`` is its path in the file (``ScaleTool 'subject01' / ModelScaler``) for messages.  Each reader
    marks its property as read; :meth:`finish` refuses the unread ones that carry a value.
    """

    def __init__(self, element: ET.Element, setup: "SetupFile", where: str):
        self.element = element
        self.setup = setup
        self.where = where
        self.name = element.get("name", "")
        self.tag = element.tag
        self._read: set = set()

    # -- raw access ----------------------------------------------------------------------
    def _find(self, prop: str):
        self._read.add(prop)
        return self.element.find(prop)

    def has(self, prop: str) -> bool:
        """Whether the property is present with a value (text or children); does not mark it read."""
        el = self.element.find(prop)
        return el is not None and _has_value(el)

    def error(self, prop: str | None, message: str) -> SetupError:
        """A :class:`SetupError` naming the file, the element and the property."""
        at = f"{self.where} / <{prop}>" if prop else self.where
        return SetupError(f"{self.setup.path}: {at}: {message}")

    # -- values ------------------------------------------------------------------------
    def text(self, prop: str, default: str | None = None) -> str | None:
        """The property's text, stripped; ``default`` when absent or empty."""
        el = self._find(prop)
        if el is None or el.text is None or not el.text.strip():
            return default
        return el.text.strip()

    def words(self, prop: str, default=()) -> list:
        """The property's whitespace-separated words (``<forces_to_exclude> Muscles </...>``)."""
        t = self.text(prop)
        return list(default) if t is None else t.split()

    def number(self, prop: str, default: float | None = None) -> float | None:
        t = self.text(prop)
        if t is None:
            return default
        try:
            return float(t)
        except ValueError:
            raise self.error(prop, f"'{t}' is not a number") from None

    def integer(self, prop: str, default: int | None = None) -> int | None:
        v = self.number(prop, None)
        if v is None:
            return default
        if v != int(v):
            raise self.error(prop, f"'{v:g}' is not a whole number")
        return int(v)

    def numbers(self, prop: str, count: int | None = None, default=None) -> list | None:
        """The property's numbers (``<time_range> 0.4 1.6 </time_range>``), ``count`` of them when given."""
        words = self.words(prop)
        if not words:
            return default
        try:
            vals = [float(w) for w in words]
        except ValueError:
            raise self.error(prop, f"'{' '.join(words)}' is not a list of numbers") from None
        if count is not None and len(vals) != count:
            raise self.error(prop, f"needs {count} numbers, got {len(vals)}")
        return vals

    def flag(self, prop: str, default: bool = False) -> bool:
        t = self.text(prop)
        if t is None:
            return default
        if t.lower() in _TRUE:
            return True
        if t.lower() in _FALSE:
            return False
        raise self.error(prop, f"'{t}' is not true or false")

    def file(self, prop: str, *, must_exist: bool = True, folder: Path | None = None) -> Path | None:
        """The property as a path, resolved against ``folder`` (default: the setup file's folder, as
        OpenSim's tools resolve it); a file that must exist and does not is refused with the resolved
        path.  None when the property is empty (or names OpenSim's ``Unassigned``)."""
        t = self.text(prop)
        if t is None or t == "Unassigned":
            return None
        p = Path(t)
        if not p.is_absolute():
            p = (folder if folder is not None else self.setup.folder) / p
        if must_exist and not p.exists():
            raise self.error(prop, f"file '{t}' not found (resolved to {p})")
        return p

    # -- nested objects ---------------------------------------------------------------
    def child(self, prop: str) -> "SetupNode | None":
        """The nested object ``prop`` (``<GenericModelMaker>``), or None when absent."""
        el = self._find(prop)
        if el is None:
            return None
        return SetupNode(el, self.setup, f"{self.where} / {prop}")

    def objects(self, prop: str, kind: str | None = None) -> list:
        """The members of the set ``prop`` (``<MeasurementSet><objects><Measurement name=...>``), each a
        :class:`SetupNode`; ``kind`` (the members' tag) is checked when given.  ``prop`` may also be an
        inline ``<objects>`` list.  An empty list when the set is absent or empty."""
        el = self._find(prop)
        if el is None:
            return []
        objs = el.find("objects")
        if objs is None:
            objs = el if prop == "objects" else None
        if objs is None:
            rest = [c.tag for c in el if c.tag not in ("groups",)]
            if rest:
                raise self.error(prop, f"holds no <objects> list (it holds {', '.join(rest)})")
            return []
        out = []
        for k, c in enumerate(objs):
            if not isinstance(c.tag, str):
                continue
            if kind is not None and c.tag != kind:
                raise self.error(prop, f"member {k + 1} is a <{c.tag}>, not a <{kind}>")
            label = c.get("name") or f"#{k + 1}"
            out.append(SetupNode(c, self.setup, f"{self.where} / {prop} / {c.tag} '{label}'"))
        groups = el.find("groups")
        if groups is not None and len(groups):
            raise self.error(prop, "groups of a set are not supported; list the members")
        return out

    # -- the check ---------------------------------------------------------------------
    def unread(self) -> list:
        """The properties present with a value that no reader took."""
        return [c.tag for c in self.element if isinstance(c.tag, str) and c.tag not in self._read
                and _has_value(c)]

    def finish(self, *, ignore=()) -> None:
        """Refuse, by name, every property with a value that was not read (``ignore``: properties that
        do not change the result, e.g. ``<notes>``)."""
        left = [p for p in self.unread() if p not in set(ignore)]
        if left:
            read = sorted(self._read | set(ignore))
            raise self.error(None, f"propert{'y' if len(left) == 1 else 'ies'} "
                                   f"{', '.join('<' + p + '>' for p in left)} not supported by pinmsk "
                                   f"(it reads {', '.join(read) if read else 'none'}); remove "
                                   f"{'it' if len(left) == 1 else 'them'} or leave {'it' if len(left) == 1 else 'them'} empty")

    def ignore(self, *props: str) -> None:
        """Mark properties as read that do not change the result (``<notes>``, ``<age>``)."""
        self._read.update(props)


def _has_value(el: ET.Element) -> bool:
    if el.text is not None and el.text.strip():
        return True
    return any(isinstance(c.tag, str) and _has_value(c) for c in el)


class SetupFile:
    """An OpenSim setup file: ``tool`` (the tool's tag, e.g. ``"InverseDynamicsTool"``), ``node`` (its
    :class:`SetupNode`), ``version`` (the document's ``Version``), ``folder`` (where paths resolve)."""

    def __init__(self, path, root: ET.Element):
        self.path = Path(path)
        self.folder = self.path.resolve().parent
        self.version = root.get("Version")
        tools = [c for c in root if isinstance(c.tag, str)]
        if len(tools) != 1:
            raise SetupError(f"{self.path}: an OpenSim setup holds one tool element under <OpenSimDocument>, "
                             f"found {len(tools)} ({', '.join(c.tag for c in tools) or 'none'})")
        el = tools[0]
        self.tool = el.tag
        self.name = el.get("name", "")
        self.node = SetupNode(el, self, f"{self.tool} '{self.name}'" if self.name else self.tool)

    def __repr__(self):
        return f"<SetupFile {self.tool} '{self.name}' from {self.path}>"


def parse_xml(path, what: str, error=SetupError) -> ET.Element:
    """The root element of the XML file ``path`` (an OpenSim ``what``: "setup file", "ExternalLoads
    file"); ``error`` (a :class:`~pinmsk.errors.PinmskError` class) names a missing file with the path it
    resolved to, and a file that is not XML with the parser's line and column."""
    p = Path(path)
    if not p.exists():
        raise error(f"{what} '{path}' not found (resolved to {p.resolve()})")
    try:
        return ET.parse(p).getroot()
    except ET.ParseError as exc:
        raise error(f"{p}: not a valid XML file ({exc})") from None
    except (LookupError, UnicodeError, ValueError) as exc:      # an encoding the declaration names but Python lacks
        raise error(f"{p}: not a readable XML file ({' '.join(str(exc).split())})") from None


def read_setup(path) -> SetupFile:
    """Read an OpenSim setup file; refused by name when it is missing, not XML, or not a setup."""
    p = Path(path)
    root = parse_xml(p, "setup file")
    if root.tag != "OpenSimDocument":
        raise SetupError(f"{p}: the root element is <{root.tag}>, not <OpenSimDocument>: not an OpenSim setup file")
    return SetupFile(p, root)
