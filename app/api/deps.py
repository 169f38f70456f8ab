"""What routes depend on: the registry, the settings, the token check."""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from app.api.errors import Unauthorized
from app.service.registry import ModelRegistry
from app.settings import Settings

bearer = HTTPBearer(auto_error=False, description="Required when the server has a token.")


# Dependencies are coroutines: FastAPI runs plain functions in the threadpool, a thread hop
# per dependency per request.


async def get_registry(request: Request) -> ModelRegistry:
    registry: ModelRegistry = request.app.state.registry
    return registry


async def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


def token_ok(expected: str | None, given: str | None) -> bool:
    """Constant-time comparison; everything passes when the server has no token."""
    if expected is None:
        return True
    return given is not None and hmac.compare_digest(given.encode(), expected.encode())


async def require_token(
    settings: Annotated[Settings, Depends(get_settings)],
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
) -> None:
    if not token_ok(settings.token, credentials.credentials if credentials else None):
        raise Unauthorized("missing or wrong bearer token")


RegistryDep = Annotated[ModelRegistry, Depends(get_registry)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
