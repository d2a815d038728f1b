"""The scenario schema's part for each controller's own settings (`controller.husky_cbf`), made
from the controller's configuration dataclass (its registry entry's `settings`): every setting that
carries a Range there (controllers.settings.setting) may be given, checked against that range,
and nothing else. So a setting's default, its range and its reason live in one place, the controller's
config, and the schema cannot drift from it."""

from __future__ import annotations

import dataclasses
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, StrictBool, create_model

from controllers import registry
from controllers.settings import nested_settings
from husky_sim.runs.ranged import ranged


class _Settings(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _model(config: type, name: str) -> type[BaseModel]:
    """A pydantic model of `config`'s ranged and boolean settings (each optional: omitted ones
    keep the default), with a sub-model for each nested settings block."""
    nested = nested_settings(config)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(config):
        allowed = f.metadata.get("range")
        if f.name in nested:
            sub = _model(nested[f.name], f"{name}_{f.name}")
            fields[f.name] = (sub | None, None)
        elif allowed is not None:
            length = len(f.default) if isinstance(f.default, tuple) else None
            fields[f.name] = (ranged(allowed, length, optional=True), None)
        elif isinstance(f.default, bool):
            fields[f.name] = (StrictBool | None, None)
    return create_model(name, __base__=_Settings, __doc__=(config.__doc__ or "").strip(), **fields)


def settings_fields() -> dict[str, Any]:
    """The `controller` block's field for each registered controller with settings of its own
    (`controller.husky_cbf`): optional, its model made from the controller's config."""
    out: dict[str, Any] = {}
    for e in registry.entries():
        if e.settings is not None:
            model = _model(e.settings, f"{e.settings.__name__}Settings")
            described = Field(default=None, description=f"{e.name}'s own settings ({e.summary})")
            out[e.settings_key] = (model | None, described)
    return out


def given_settings(spec: BaseModel, name: str) -> dict[str, Any]:
    """The settings a scenario's `controller` block gave the controller `name` (nested blocks as
    dicts, omitted ones left out): what its `configure` applies."""
    block = getattr(spec, registry.entry(name).settings_key, None)
    return {} if block is None else block.model_dump(exclude_none=True)
