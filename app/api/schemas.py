"""Request and response bodies of the API, each field described for the OpenAPI schema."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field

from app.service.registry import NAME

FiniteFloat = Annotated[float, Field(allow_inf_nan=False, strict=True)]
NAME_PATTERN = f"^{NAME.pattern}$"  # the only patterned input: errors.py relies on that
ModelName = Annotated[str, Field(pattern=NAME_PATTERN, examples=["default", "run-3"])]

STEP_EXAMPLE: dict[str, Any] = {"observation": [14.2, 38.5, 15.0], "action": 0.8, "stream": "car-1"}


class ReviseRequest(BaseModel):
    """One step of a stream: the observation at t and the action the controller proposes."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [STEP_EXAMPLE]})

    observation: list[FiniteFloat] = Field(
        min_length=1,
        max_length=1024,
        description="z_t in physical units, one number per configured dimension (the car-"
        "following model: ego speed [m/s], headway [m], lead speed [m/s]).",
        examples=[[14.2, 38.5, 15.0]],
    )
    action: FiniteFloat | None = Field(
        None,
        description="The proposed action a_t (m/s²); null only when done is true.",
        examples=[0.8],
    )
    stream: str = Field(
        "0",
        min_length=1,
        max_length=128,
        strict=True,
        description="Which stream this step belongs to.",
        examples=["car-1"],
    )
    event: str | None = Field(
        None,
        strict=True,
        description="A criterion observed at z_t ('collision', 'large_distance', ...): the "
        "recognised state is flagged with it.",
        examples=["collision"],
    )
    done: bool = Field(
        False,
        strict=True,
        description="z_t ends the episode: learn from it, then forget the stream's previous step.",
    )
    applied_action: FiniteFloat | None = Field(
        None,
        description="The action really executed at t-1, when it differs from the one "
        "returned (e.g. the vehicle clipped it).",
        examples=[-0.4],
    )
    learn: bool = Field(
        True, strict=True, description="False: answer without changing the model (what-if)."
    )
    shadow: bool = Field(
        False,
        strict=True,
        description="True: learn and report what would be done, but return the proposed action.",
    )
    idempotency_key: str | None = Field(
        None,
        min_length=1,
        max_length=128,
        strict=True,
        description="Names this step (a fresh UUID, say) so that it can be sent again safely: "
        "a step whose key the model remembers (its last idempotency_window keyed steps, "
        "across restarts) is answered with its first decision and not applied again; a key "
        "sent with another step is refused (422 idempotency_key_reused).",
        examples=["3f0c2a4e9b7d4c1e8a6f5b2d0e9c7a18"],
    )


class ModelStep(ReviseRequest):
    """A step that names its model, for batches across models."""

    model: ModelName = Field(description="The model this step feeds.")


class BatchRequest(BaseModel):
    """Steps applied in order; one bad step rejects the whole batch."""

    model_config = ConfigDict(extra="forbid")
    steps: list[ReviseRequest] = Field(description="The steps, in order.")


class ModelBatchRequest(BaseModel):
    """Steps across models (one per vectorised run, say), applied in order."""

    model_config = ConfigDict(extra="forbid")
    steps: list[ModelStep] = Field(description="The steps, each naming its model.")


class Candidate(BaseModel):
    """An action the reviser inspected."""

    action: float = Field(
        description="The action the bin applies (m/s²): its midpoint, or "
        "with the risk reviser the range's end for an end bin."
    )
    bin: int = Field(description="The action bin, 0 = hardest braking.")
    verdict: str = Field(description="'ok' or the criterion predicted for it.")
    risk: dict[str, float] | None = Field(
        default=None,
        description="The risk reviser's risk of each failure for this action: "
        "the mean of the local model's probability within its horizon and the reach's "
        "(the closeness to a failure under the safest continuation); null for the paper's "
        "reviser.",
    )


class Decision(BaseModel):
    """The decision record of one step."""

    action: float | None = Field(description="The action to apply; null when done.")
    proposed: float | None = Field(description="The proposed action, echoed.")
    revised: bool = Field(
        description="Whether the reviser changed (or, in shadow mode, "
        "would have changed) the action."
    )
    reason: str = Field(
        description="pass, revised_safety, revised_speed, backed_off (the "
        "risk reviser passed the proposal where its revisions were followed "
        "by more failures; suggested holds the revision), audit (an episode "
        "the shield leaves to the controller, to compare; suggested holds the "
        "revision), inactive, cold_start or done."
    )
    verdict: str = Field(description="What inspecting the proposed action found.")
    risk: dict[str, float] = Field(
        description="The proposed action's risk per criterion: the "
        "mean of the probability of that failure within the "
        "horizon and the reach's (risk reviser), or the predicted "
        "mass on flagged states (paper)."
    )
    threshold: float | None = Field(
        description="Alg. 1's adaptive threshold for the "
        "proposed action (paper reviser) or the largest total "
        "risk an action may carry and be applied, the least "
        "total risk plus the margin (risk reviser); null when "
        "nothing was inspected."
    )
    candidates: list[Candidate] = Field(description="Actions inspected while revising.")
    state: int | None = Field(description="The recognised state (argmax belief).")
    n_states: int = Field(description="States after this step.")
    new_state: bool = Field(description="This step created a state.")
    episode: int = Field(description="Finished episodes of the model.")
    step: int = Field(description="This stream's step within its episode.")
    model_version: int = Field(description="Increases with every learning step.")
    stream: str = Field(description="The stream, echoed.")
    shadow: bool = Field(description="The step ran in shadow mode.")
    suggested: float | None = Field(
        description="The action the reviser would return (equals action unless shadow)."
    )


class BatchResponse(BaseModel):
    """Decisions in the order of the steps."""

    decisions: list[Decision]


class ModelCreate(BaseModel):
    """A new model."""

    model_config = ConfigDict(extra="forbid")
    name: ModelName = Field(description="Its name.")
    config: dict[str, Any] = Field(
        default_factory=dict,
        description="Overrides of the paper's car-following configuration: observation "
        "(names, low, high, knee, features, cluster_raw), "
        "action (low, high, step, out_of_range), "
        "criteria ([{name, direction (decrease, increase or null), "
        "bound: {observation, below, above} or null}]), "
        "clustering (rho, epsilon, creation_rule, spread, min_variance), "
        "transitions (learning_rate, prior, on_new_state, expansion, action_source, "
        "across_episodes, on_replace), reviser (activate_after_episodes, noise_k, noise, "
        "horizon, transpose, inspect, search, multi_step, flags, flag_min_rate, one_sided, "
        "seed, method: risk or paper), "
        "risk (horizon, threshold, margin, reach_horizon, reach_radius), "
        "limits (max_states, max_streams, belief_top_k, tpm_backend).",
        examples=[{"clustering": {"epsilon": 0.1}, "reviser": {"seed": 7}}],
    )


class ModelSummary(BaseModel):
    """A model's counters."""

    name: str
    n_states: int
    steps: int = Field(description="Learning steps so far.")
    episodes: int = Field(description="Finished episodes.")
    model_version: int
    interventions: dict[str, int] = Field(description="Revised actions per criterion.")
    streams: int = Field(description="Streams with an open episode.")


class ModelList(BaseModel):
    models: list[ModelSummary]


class HistoryTotals(BaseModel):
    """A model's totals now."""

    episodes: int = Field(description="Finished episodes.")
    steps: int = Field(description="Learning steps (an episode's closing step included).")
    n_states: int = Field(description="States.")
    model_version: int
    interventions: dict[str, int] = Field(description="Revised actions per criterion.")
    failures: dict[str, int] = Field(description="Failures (events learned) per criterion.")


class ModelHistory(BaseModel):
    """A model's totals at the end of its episodes, one list per column (row k of every
    list belongs together), and its totals now. Any two rows give what happened between
    them: revisions per episode are the difference of ``interventions`` over the difference
    of ``episodes``; the share of revised actions divides by the difference of ``steps``
    less that of ``episodes`` (the closing steps propose no action)."""

    name: str
    stride: int = Field(
        description="Episodes between two rows: 1 until the history holds "
        "`limit` rows, then doubled each time it fills (every other row "
        "dropped), so that the rows span the model's whole life.",
        examples=[1],
    )
    limit: int = Field(description="The most rows a model keeps.", examples=[512])
    episodes: list[int] = Field(
        description="Finished episodes at each row: a multiple of `stride`.", examples=[[1, 2, 3]]
    )
    steps: list[int] = Field(description="Learning steps by then.", examples=[[26, 51, 77]])
    n_states: list[int] = Field(description="States by then.", examples=[[4, 6, 6]])
    interventions: dict[str, list[int]] = Field(
        description="Revised actions per criterion by then.",
        examples=[{"collision": [0, 3, 5], "large_distance": [0, 0, 1]}],
    )
    failures: dict[str, list[int]] = Field(
        description="Failures (events learned) per criterion by then.",
        examples=[{"collision": [1, 1, 2], "large_distance": [0, 0, 0]}],
    )
    totals: HistoryTotals = Field(description="The totals now, from which a live view goes on.")


class ErrorDetail(BaseModel):
    code: str = Field(
        description="Stable machine-readable code: invalid_json, invalid_body, invalid_query, "
        "invalid_observation, invalid_action, unknown_criterion, invalid_name, invalid_config, "
        "invalid_snapshot, idempotency_key_reused (422); unknown_model, not_found (404); "
        "model_exists, too_many_models (409); too_large (413); unauthorized (401); "
        "model_quarantined (503); unsupported_frame (a binary WebSocket frame).",
        examples=["invalid_body"],
    )
    message: str = Field(description="What is wrong, for people.")
    field: str | None = Field(
        None, description="The input at fault, dotted.", examples=["observation"]
    )


class ErrorBody(BaseModel):
    """Every error has this shape."""

    error: ErrorDetail
