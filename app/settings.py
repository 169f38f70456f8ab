"""Server settings: environment variables (``EFSM_*``) and the command line, one typed source."""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field, FilePath, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from app.core import ShieldConfig, ShieldError


class Settings(BaseSettings):
    """How the shield service runs. Every field is also ``EFSM_<NAME>`` in the environment."""

    model_config = SettingsConfigDict(
        env_prefix="EFSM_",
        cli_kebab_case=True,
        cli_prog_name="python -m app serve",
        cli_implicit_flags=True,
    )

    host: str = Field("127.0.0.1", description="Address to bind (0.0.0.0 in the container).")
    port: int = Field(8000, ge=0, le=65535, description="TCP port.")
    data_dir: Path | None = Field(
        None, description="Where models are stored; without it models live in memory only."
    )
    fsync: Literal["always", "interval", "never"] = Field(
        "interval",
        description="When the journal reaches the disk: on every accepted request, at most one "
        "second later, or when the operating system decides.",
    )
    token: str | None = Field(
        None, description="Bearer token every route but /healthz and /readyz requires."
    )
    config: FilePath | None = Field(
        None, description="JSON file with the configuration of the 'default' model."
    )
    max_body_bytes: int = Field(8 * 2**20, ge=1024, description="Largest request body (413).")
    max_snapshot_bytes: int = Field(
        256 * 2**20,
        ge=1024,
        description="Largest snapshot uploaded with PUT /models/{name} (413), and the most its "
        "arrays may take once read (422 invalid_snapshot).",
    )
    max_batch: int = Field(4096, ge=1, description="Most steps in one batch request.")
    max_models: int = Field(1000, ge=1, description="Most models this server holds (409).")
    max_states: int = Field(
        100_000,
        ge=1,
        le=1_000_000,
        description="The largest limits.max_states a model of this server may have (422).",
    )
    max_action_bins: int = Field(
        256,
        ge=2,
        le=4096,
        description="The most action bins (the range over the step) a model may have (422).",
    )
    max_dimensions: int = Field(
        64,
        ge=1,
        le=1024,
        description="The most observation names and features together a model may have (422).",
    )
    max_model_bytes: int = Field(
        256 * 2**20,
        ge=2**20,
        description="The most memory a model's tables may take once it holds its "
        "limits.max_states states and limits.max_streams streams, by the server's estimate "
        "(422, naming limits.max_states; the default configuration takes about 120 MiB). "
        "Keep it within max_snapshot_bytes, so that every model's snapshot restores.",
    )
    max_concurrent_restores: int = Field(
        2,
        ge=1,
        le=64,
        description="Snapshots read at once by PUT /models/{name}; more wait their turn. "
        "Each takes up to about twice max_snapshot_bytes while it is read.",
    )
    snapshot_every: int = Field(
        50_000, ge=1, description="Steps of a model between two snapshots of it."
    )
    idempotency_window: int = Field(
        1024,
        ge=1,
        le=65_536,
        description="Steps sent with an idempotency key that each model remembers (the last "
        "ones, about 0.5 KB each): a step sent again within them is answered with its first "
        "decision, not applied again; one request carries at most this many keyed steps of a "
        "model (413).",
    )
    header_timeout: float = Field(
        10.0,
        gt=0,
        le=3600,
        description="Seconds a request's line and headers may take to arrive, from the "
        "connection's opening or the request's first byte (then 408 and the connection closes).",
    )
    body_timeout: float = Field(
        20.0,
        gt=0,
        le=3600,
        description="Longest pause, in seconds, between two reads of a request's body (408).",
    )
    keep_alive_timeout: int = Field(
        5, ge=1, le=3600, description="Seconds an idle kept-alive connection stays open."
    )
    max_connections: int = Field(
        1000,
        ge=1,
        description="Most connections open at once, HTTP and WebSocket; one more is answered "
        "503 and closed. Keep it under the process's open-file limit (ulimit -n).",
    )
    log_level: Literal["debug", "info", "warning", "error"] = "info"

    @field_validator("token")
    @classmethod
    def _token_not_blank(cls, value: str | None) -> str | None:
        if value is not None and not value.strip():
            raise ValueError("a token that is set must not be empty")
        return value

    @field_validator("config")
    @classmethod
    def _config_is_a_shield_configuration(cls, value: Path | None) -> Path | None:
        """Refuse a file that is not a shield configuration when the settings are read, not
        when the service starts, so that the error names the setting."""
        if value is None:
            return value
        try:
            ShieldConfig.from_dict(json.loads(value.read_text()))
        except OSError as error:
            raise ValueError(f"{value}: {error.strerror}") from error
        except ShieldError as error:
            field = f"{error.field}: " if error.field else ""
            raise ValueError(f"{value}: {field}{error.message}") from error
        except ValueError as error:  # not JSON
            raise ValueError(f"{value}: not JSON: {error}") from error
        return value


class ClusterSettings(Settings):
    """``python -m app serve-ray``: the service sharded on Ray Serve (:mod:`app.cluster`)."""

    # merged into the inherited configuration: only the program name differs
    model_config = SettingsConfigDict(cli_prog_name="python -m app serve-ray")

    shards: int = Field(
        2,
        ge=1,
        le=1024,
        description="Shards; each owns the models whose "
        "names it wins, and keeps its files under <data-dir>/shards/<i>.",
    )
    ingresses: int = Field(
        1,
        ge=1,
        le=1024,
        description="Ingress replicas (each takes any request; Serve spreads requests over them).",
    )
    ray_address: str | None = Field(
        None,
        description="An existing Ray cluster ('auto', or ray://host:port); without it a "
        "local Ray instance starts and stops with the service.",
    )
    ray_cpus: int | None = Field(None, ge=1, description="CPUs of the local Ray instance.")
    ray_object_store_mb: int = Field(
        256, ge=64, description="Object store of the local Ray instance (MiB)."
    )


@lru_cache
def get_settings() -> Settings:
    """The settings of this process (tests build their own :class:`Settings`)."""
    return Settings()
