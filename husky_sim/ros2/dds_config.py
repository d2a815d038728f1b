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

Everything else of the user's (tracing, participant indices, buffer sizes, shared memory, ...)
applies unchanged. A fragment Cyclone DDS accepts but a strict XML parser does not (Cyclone DDS's
`</>` shorthand) passes through as it is. A file that cannot be read, or a merged configuration
that Cyclone DDS refuses, is a DdsConfigError: one line, with Cyclone DDS's own reason.
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

#: Elements that place a participant on the network; a localhost-only participant sets them itself.
NETWORK_PLACEMENT = ("Interfaces", "NetworkInterfaceAddress", "AllowMulticast", "Peers")

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


def _read(item: str) -> str:
    """An item's XML: the item itself, or the file it names (file:// URI or path)."""
    if item.startswith("<"):
        return item
    path = item[len("file://") :] if item.startswith("file://") else item
    try:
        return Path(path).read_text()
    except OSError as exc:
        raise DdsConfigError(f"{URI_VARIABLE}: cannot read {item[:200]}: {exc.strerror or exc}") from None


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
    for item in split_uri(uri):
        text = _read(item).strip()
        try:
            root = ET.fromstring(text)
        except ET.ParseError:  # not strict XML (Cyclone DDS's shorthand): Cyclone DDS judges it
            fragments.append(text)
            continue
        for element in root.iter():
            if _local(element.tag) == "ignoretypeinformation" and element.text:
                vendors += [v.strip() for v in element.text.split(",") if v.strip()]
        if localhost_only:
            removed = _set_aside(root, NETWORK_PLACEMENT)
            if removed:
                set_aside += removed
                _without_namespaces(root)
                text = ET.tostring(root, encoding="unicode") if len(root) or root.text else ""
        if text:
            fragments.append(text)
    ours = [compatibility_config(tuple(vendors)), *([LOCALHOST_ONLY_CONFIG] if localhost_only else [])]
    return MergedConfig(",".join([*fragments, *ours]), tuple(dict.fromkeys(set_aside)))


_LOG_PREFIX = re.compile(r"^\d+\.\d+\s+\[\d*\]\s+[^:]*:\s*")


def refusal(log: str) -> str:
    """Cyclone DDS's reason for refusing a configuration, from what it wrote to stderr."""
    lines = [_LOG_PREFIX.sub("", line).strip() for line in log.splitlines() if line.strip()]
    return "; ".join(lines[-3:]) if lines else "no reason given"
