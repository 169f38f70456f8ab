"""What routes depend on: the registry, the settings, the token check."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import Depends, Request
from fastapi.security import HTTPBearer

from app.api.auth import given_token, token_ok
from app.api.errors import Unauthorized
from app.service.registry import ModelRegistry
from app.settings import Settings

# Dependencies are coroutines: FastAPI runs plain functions in the threadpool, a thread hop
# per dependency per request.


async def get_registry(request: Request) -> ModelRegistry:
    registry: ModelRegistry = request.app.state.registry
    return registry


async def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


def check_token(request: Request) -> None:
    """Raise :class:`Unauthorized` unless the request carries the server's bearer token."""
    expected = request.app.state.settings.token
    if expected is None:
        return
    if not token_ok(expected, given_token(request.headers, {})):  # the header only
        raise Unauthorized("missing or wrong bearer token")


class BearerToken(HTTPBearer):
    """The bearer scheme of the OpenAPI schema, checked in a single dependency."""

    async def __call__(self, request: Request) -> None:  # type: ignore[override]
        check_token(request)


require_token = BearerToken(auto_error=False, description="Required when the server has a token.")
# Routes on the per-step path call check_token themselves (a FastAPI dependency costs about
# 25 us a request) and document the scheme with this
BEARER_DOCUMENTED: dict[str, Any] = {"security": [{require_token.scheme_name: []}]}

RegistryDep = Annotated[ModelRegistry, Depends(get_registry)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
