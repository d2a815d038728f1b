"""The scenario schema's part for each controller's own settings (`controller.husky_cbf`), made
from the controller's configuration dataclass (its registry entry's `settings`): every setting that
carries a Range there (controllers.settings.setting) may be given, checked against that range,
and nothing else. So a setting's default, its range and its reason live in one place, the controller's
config, and the schema cannot drift from it."""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, StrictBool, create_model

from controllers import registry
from controllers.settings import Range, nested_settings


class _Settings(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _field_type(allowed: Range, default: object) -> Any:
    """An optional field taking what `allowed` contains (one value, or a tuple of them as long as
    the default); None: not given. The error names the range."""
    length = len(default) if isinstance(default, tuple) else None
    kind = "an integer" if allowed.integer else "a finite number"
    message = f"must be {kind} in {allowed.text()}"
    if length is not None:
        message = f"must be {length} entries, each {kind} in {allowed.text()}"

    def check(value: object) -> object:
        if value is None:
            return None
        values = value if length is not None else (value,)
        if length is not None and (not isinstance(value, list | tuple) or len(value) != length):
            raise ValueError(message)
        if not all(allowed.contains(v) for v in values):
            raise ValueError(message)
        if length is not None:
            return tuple(float(v) for v in values)
        return value if allowed.integer else float(value)

    number: Any = int if allowed.integer else float
    kind_type: Any = tuple[(number,) * length] if length is not None else number
    shown = Field(default=None, json_schema_extra={"range": allowed.text()})  # for the docs
    return Annotated[kind_type | None, BeforeValidator(check), shown]


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
            fields[f.name] = (_field_type(allowed, f.default), None)
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
