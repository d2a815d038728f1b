"""Cyclone DDS's configuration for our participants: the user's CYCLONEDDS_URI merged with ours.

Cyclone DDS reads CYCLONEDDS_URI as a comma-separated list of XML fragments and file URIs and
applies them in order: a later value of a setting overrides an earlier one, while list elements
(network interfaces, peers) accumulate. Ours come after the user's:
- **always**, the compatibility fragment (Fast DDS's endpoints matched by type name, see
  husky_sim.ros2.cyclone_transport), its vendor list joined with any the user's configuration names;
- **localhost-only** (rehearsals, `serve --localhost-only`), loopback only: one interface, no
  multicast, unicast discovery to 127.0.0.1. The user's network placement (`Interfaces`,
  `NetworkInterfaceAddress`, `AllowMulticast`, `Peers`) is set aside and named in a notice: such a
  participant must never reach a robot on the network, and Cyclone DDS refuses a configuration that
  selects one interface twice.

Everything else of the user's (tracing, buffer sizes, shared memory, ...) applies, but for the
settings our fragments set after theirs (localhost-only: the participant index and its range, the
heartbeat interval). Files and `${VAR}`s in the URI are read here, as Cyclone DDS reads them; a
file that needs nothing set aside is handed on by name. A fragment Cyclone DDS accepts but a strict
XML parser does not (its `</>` shorthand) passes through as it is on the network, and is refused
for a localhost-only participant, whose network placement must be read to be set aside. A file
that cannot be read, such a fragment, or a merged configuration that Cyclone DDS refuses, is a
DdsConfigError: one line, with Cyclone DDS's own reason where it gave one.
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

#: The user's Cyclone DDS configuration (Cyclone DDS's own variable).
URI_VARIABLE = "CYCLONEDDS_URI"

#: Vendor ids whose endpoints are matched by type name: eProsima's (Fast DDS).
IGNORE_TYPE_INFORMATION_VENDORS = ("1.15",)

#: Elements that place a participant on the network (the last three deprecated, which Cyclone DDS
#: refuses beside `Interfaces`); a localhost-only participant sets its placement itself.
NETWORK_PLACEMENT = (
    "Interfaces",
    "NetworkInterfaceAddress",
    "AllowMulticast",
    "Peers",
    "AssumeMulticastCapable",
    "MulticastRecvNetworkInterfaceAddresses",
    "PreferMulticast",
)

#: Loopback only: no multicast, discovery by unicast to 127.0.0.1. Reliable writers heartbeat
#: every 5 ms instead of 100 ms, so a write is acknowledged within about a millisecond (a rehearsal
#: robot waits for the node's acknowledgement of the obstacles each step).
LOCALHOST_ONLY_CONFIG = """<CycloneDDS><Domain id="any">
<General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>
<AllowMulticast>false</AllowMulticast></General>
<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30</MaxAutoParticipantIndex>
<Peers><Peer address="127.0.0.1"/></Peers></Discovery>
<Internal><HeartbeatInterval min="1 ms" minsched="1 ms">5 ms</HeartbeatInterval></Internal>
</Domain></CycloneDDS>"""


class DdsConfigError(ValueError):
    """The user's Cyclone DDS configuration cannot be used (one line, naming CYCLONEDDS_URI)."""


@dataclass(frozen=True)
class MergedConfig:
    """The configuration a domain is created with, and the user's elements set aside for it."""

    xml: str
    set_aside: tuple[str, ...] = ()

    def notice(self) -> str | None:
        """One line for the user when some of their configuration was set aside, else None."""
        if not self.set_aside:
            return None
        names = ", ".join(f"<{name}>" for name in self.set_aside)
        return f"{URI_VARIABLE}: {names} set aside: a localhost-only participant keeps DDS on 127.0.0.1"


def compatibility_config(user_vendors: tuple[str, ...] = ()) -> str:
    vendors = ",".join(dict.fromkeys((*user_vendors, *IGNORE_TYPE_INFORMATION_VENDORS)))
    return (
        '<CycloneDDS><Domain id="any"><Compatibility>'
        f"<IgnoreTypeInformation>{vendors}</IgnoreTypeInformation>"
        "</Compatibility></Domain></CycloneDDS>"
    )


_TAG = re.compile(r"<(/?)([^\s/>!?]*)[^>]*?(/?)>")


def split_uri(uri: str) -> list[str]:
    """CYCLONEDDS_URI's items in order: each XML fragment whole (commas inside it kept), each file
    URI or path as written."""
    items: list[str] = []
    i, n = 0, len(uri)
    while i < n:
        while i < n and (uri[i].isspace() or uri[i] == ","):
            i += 1
        if i >= n:
            break
        if uri[i] != "<":
            end = uri.find(",", i)
            end = n if end < 0 else end
            items.append(uri[i:end].strip())
            i = end
            continue
        depth, end = 0, n
        for tag in _TAG.finditer(uri, i):
            closing, _name, self_closing = tag.groups()
            if uri[tag.start() + 1] in "!?" or self_closing:
                pass
            elif closing:
                depth -= 1
            else:
                depth += 1
            if depth <= 0:
                end = tag.end()
                break
        items.append(uri[i:end])
        i = end
    return items


def _path(item: str) -> str | None:
    """The file an item names (file:// URI or path, `${VAR}`s expanded), or None for XML."""
    if item.startswith("<"):
        return None
    return os.path.expandvars(item[len("file://") :] if item.startswith("file://") else item)


def _read(item: str) -> bytes:
    """An item's XML: the item itself, or the file it names, as bytes (a file's declared encoding
    is the XML parser's to read)."""
    path = _path(item)
    if path is None:
        return item.encode()
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise DdsConfigError(f"{URI_VARIABLE}: cannot read {item[:200]}: {exc.strerror or exc}") from None


def _ascii_xml(root: ET.Element) -> str:
    """An element as XML in ASCII (other characters as references): Cyclone DDS's Python binding
    hands a configuration on as ASCII."""
    return ET.tostring(root, encoding="us-ascii", xml_declaration=False).decode("ascii")


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1].lower()


def _without_namespaces(root: ET.Element) -> None:
    """Drop XML namespaces (`xmlns="https://cdds.io/config"`, `xsi:schemaLocation`), so the
    fragment serialises without prefixes Cyclone DDS would not read."""
    for element in root.iter():
        element.tag = element.tag.rsplit("}", 1)[-1]
        for key in [k for k in element.attrib if k.startswith("{")]:
            del element.attrib[key]


def _set_aside(root: ET.Element, names: tuple[str, ...]) -> list[str]:
    """Remove every element named in `names` (any depth, any case); return the names removed."""
    wanted = {name.lower(): name for name in names}
    removed: list[str] = []
    for parent in list(root.iter()):
        for child in list(parent):
            name = wanted.get(_local(child.tag))
            if name is not None:
                parent.remove(child)
                removed.append(name)
    if _local(root.tag) in wanted:  # a fragment that is nothing but a placement element
        removed.append(wanted[_local(root.tag)])
        root.clear()
    return removed


def merged_config(localhost_only: bool, environ: dict[str, str] | None = None) -> MergedConfig:
    """The user's configuration (CYCLONEDDS_URI, may be unset) followed by ours."""
    uri = (os.environ if environ is None else environ).get(URI_VARIABLE, "").strip()
    fragments: list[str] = []
    set_aside: list[str] = []
    vendors: list[str] = []
    for number, item in enumerate(split_uri(uri), start=1):
        raw = _read(item).strip()
        try:
            root = ET.fromstring(raw)
        except ET.ParseError as exc:
            if localhost_only:
                raise DdsConfigError(
                    f"{URI_VARIABLE}: item {number} is not strict XML ({exc}); a localhost-only "
                    "participant reads the network placement to set it aside: close every element "
                    "by name"
                ) from None
            fragments.append(raw.decode(errors="replace") if _path(item) is None else f"file://{_path(item)}")
            continue
        for element in root.iter():
            if _local(element.tag) == "ignoretypeinformation" and element.text:
                vendors += [v.strip() for v in element.text.split(",") if v.strip()]
        removed = _set_aside(root, NETWORK_PLACEMENT) if localhost_only else []
        if removed:
            set_aside += removed
            _without_namespaces(root)
            if len(root) or root.text:
                fragments.append(_ascii_xml(root))
        elif _path(item) is not None:
            fragments.append(f"file://{_path(item)}")  # Cyclone DDS reads it as the user wrote it
        else:
            fragments.append(item if item.isascii() else _ascii_xml(root))
    ours = [compatibility_config(tuple(vendors)), *([LOCALHOST_ONLY_CONFIG] if localhost_only else [])]
    return MergedConfig(",".join([*fragments, *ours]), tuple(dict.fromkeys(set_aside)))


_LOG_PREFIX = re.compile(r"^\d+\.\d+\s+\[\d*\]\s+[^:]*:\s*")


def refusal(log: str) -> str:
    """Cyclone DDS's reason for refusing a configuration, from what it wrote to stderr: its
    configuration and error lines where there are any (a user's tracing may share stderr), else
    its last lines."""
    lines = [_LOG_PREFIX.sub("", line).strip() for line in log.splitlines() if line.strip()]
    reasons = [line for line in lines if line.startswith("config:") or "error" in line.lower()]
    return "; ".join((reasons or lines)[-3:]) if lines else "no reason given (see its log)"
