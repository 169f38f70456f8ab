"""What routes depend on: the registry, the settings, the token check, the known query."""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Annotated, Any

from fastapi import Depends, Request, Response
from fastapi.dependencies.models import Dependant
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
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


class KnownQueryRoute(APIRoute):
    """A route that refuses a query parameter it does not take, as an unknown body field is
    refused (422 ``invalid_query`` naming it; 401 first without the token), so that a misspelt
    option (``?tmp=none``) is not ignored without a word. A request without a query string pays
    one test; the routers name it as their ``route_class``."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()
        taken = query_names(self.dependant)
        takes = f"takes {', '.join(sorted(taken))}" if taken else "takes no query parameters"

        async def checked(request: Request) -> Response:
            if request.scope["query_string"]:
                for name, value in request.query_params.multi_items():
                    if name not in taken:
                        raise RequestValidationError(
                            [
                                {
                                    "type": "extra_forbidden",
                                    "loc": ("query", name),
                                    "input": value,
                                    "msg": f"unknown query parameter; this route {takes}",
                                }
                            ]
                        )
            return await handler(request)

        return checked


def query_names(dependant: Dependant) -> frozenset[str]:
    """The query parameters of a route and of everything it depends on."""
    names = {param.alias for param in dependant.query_params}
    for inner in dependant.dependencies:
        names |= query_names(inner)
    return frozenset(names)
