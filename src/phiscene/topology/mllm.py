"""``mllm`` backend: support topology from a multimodal LLM, with the paper's prompts (supplement, "Prompts for
Supporting Topology Inference").

Inputs sent: the reference image, the instance segmentation and a JSON list of per-object metadata
(:func:`object_metadata`: id, description, instance RGB colour, world AABB, OBB, top-down footprint), with
the paper's system prompt (:data:`SYSTEM_PROMPT`) and user prompt (:func:`user_prompt`, ending in the
object list). A scene with walls (its ``structure``: given, or estimated by :mod:`phiscene.walls`) also lists
them in the metadata (``walls``: name, normal, offset) and the prompt names them as supporters of what leans on
them (relation ``leans_on``); a scene without walls gets the paper's prompt unchanged. The images are found as
``params.image`` / ``params.segmentation``, else next to the
scene's camera file, else in ``../reference/`` of the scene file (the benchmark layout).

Providers (optional extra ``mllm``: ``pip install 'phiscene[mllm]'``, imported lazily):

``gemini``
    ``google-genai`` (``genai.Client(...).models.generate_content``; JSON response MIME type); the paper
    uses ``gemini-2.5-flash``. Key from ``$GEMINI_API_KEY`` unless ``api_key_env`` says otherwise.
``openai``
    ``openai`` chat completions against any OpenAI-compatible endpoint (``base_url``; images as
    ``data:`` URLs, ``response_format={"type": "json_object"}``). Key from ``$OPENAI_API_KEY``.

The key is read from the environment only and never logged or cached. Each request has a ``timeout``;
timeouts, connection errors, HTTP 429 and 5xx are retried ``max_retries`` times with exponential backoff
(``backoff * 2**attempt`` seconds). Raw responses are cached in ``cache_dir`` under the SHA-256 of the
request (provider, model, base URL, temperature, prompts, metadata, image bytes), so a rerun sends nothing.

Parsing (:func:`parse_response`) is strict JSON, then validation against the scene. With ``repair: true``
(default) these repairs are applied and listed in the graph's ``meta.repairs``; with ``repair: false``
each is an error (:class:`MllmResponseError`, naming the cached response file):

* text around the JSON object (a Markdown code fence, a preamble) is stripped;
* the ground is ``Plane`` (the prompt's schema) or ``ground``; other spellings (``floor``, ``PLANE``,
  ``ground plane``) are read as the ground; object names are matched case-insensitively;
* edges naming unknown objects, self loops and edges into the ground or a wall are dropped; duplicate edges keep the
  most confident one; a relation other than ``supports``/``leans_on``/``contains``/``attached`` becomes ``supports``;
  a missing confidence becomes ``default_confidence``;
* an object without any supporter gets ``ground -> object`` with ``fallback_confidence`` (the prompt's
  own rule for undetermined support).

Never repaired: text that holds no parseable JSON object, a top level without an ``edges`` list, edges that
are not objects with string ``from``/``to``, and confidences that are not numbers in [0, 1]. Cycles are
broken at their lowest-confidence edge (:func:`phiscene.topology.order.break_cycles`), as for every backend.
"""

from __future__ import annotations

import base64
import hashlib
import json
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from phiscene.atomic import write_text
from phiscene.errors import PhisceneError
from phiscene.meshes import oriented_box
from phiscene.topology.graph import GROUND, SupportEdge, SupportGraph, check_graph
from phiscene.topology.order import box_footprint_area, finalize
from phiscene.topology.params import BackendParams

log = logging.getLogger(__name__)

#: The paper's system prompt, verbatim.
SYSTEM_PROMPT = (
    "You are a careful 3D scene reasoning assistant.\n"
    "You will infer object support dependencies from a scene image, a color segmentation image, and scene metadata "
    "containing object names, colors, and oriented bounding boxes.\n"
    "The ground plane must be included as a valid support object.\n"
    "Every object listed in the metadata must appear in your output.\n"
    "Return strict JSON only."
)

_USER_PROMPT = """You are given:
1. A scene image.
2. A segmentation image where each object is shown in a unique flat color.
3. A JSON file including each object's description, instance RGB color, and metadata (OBB, AABB, Footprint).

Task:
- Infer support dependencies as directed edges from the supporting object to the supported object.
- Include the ground plane if it supports objects.
- Use the segmentation colors and metadata object names exactly as given.
- Prefer physically plausible load-bearing support rather than merely visual overlap.
- A single object may support multiple objects, and a single object may also be supported by multiple objects simultaneously.
If such configurations are physically plausible, return all corresponding support edges.
- Support includes all physically meaningful contact relations, not only being vertically on top.
This includes any contact that contributes to an object's physical support or stability, such as leaning contact and other non-vertical contact.
- If object A is supported by object B, output an edge B -> A.
- If you cannot determine the support source for an object (e.g., it is fully occluded),
  assume it rests on the ground and add a ground -> object edge with low confidence.
- An object fixed to a wall or the ceiling (a poster, painting, window, curtain, whiteboard, wall clock,
  ceiling fan, hanging lamp) is not supported from below: add one ground -> object edge with relation "attached".
- A visible fragment of a larger object whose lower part is hidden (the top of a chair seen behind a table, a
  cabinet cut off by the image border) stands on the ground through its hidden part: add one ground -> object
  edge with relation "attached".

Return strict JSON with this schema:
{
  "objects": ["Plane", "object_01", "..."],
  "edges": [
    {
      "from": "supporting_object_name",
      "to": "supported_object_name",
      "relation": "supports",
      "confidence": 0.0-1.0,
      "reason": "short explanation"
    }
  ]
}

Object list (every name below must appear in "objects"):
"""

#: Names the ground may be given in a response (compared lower-case).
GROUND_ALIASES = ("plane", "ground", "floor", "ground plane", "ground_plane")
RELATIONS = ("supports", "leans_on", "contains", "attached")
PROVIDERS = ("gemini", "openai")
DEFAULT_KEY_ENV = {"gemini": "GEMINI_API_KEY", "openai": "OPENAI_API_KEY"}


class MllmError(PhisceneError):
    """The MLLM could not be reached or configured (missing package or key, retries exhausted).

    Not the scene's fault: the job fails (``per_scene = False``) instead of recording the scene as failed.
    """

    per_scene = False


class MllmResponseError(PhisceneError):
    """The MLLM's answer is unusable (not JSON, wrong shape, or a repair that ``repair: false`` forbids)."""


@dataclass(frozen=True)
class MllmParams(BackendParams):
    """Parameters of the ``mllm`` backend (``config.yaml`` ``topology.mllm``).

    Attributes
    ----------
    provider
        ``gemini`` (google-genai) or ``openai`` (any OpenAI-compatible endpoint).
    model
        Model name (the paper: ``gemini-2.5-flash``).
    base_url
        Endpoint override (OpenAI-compatible servers, proxies, a local fake in tests).
    api_key_env
        Environment variable holding the API key (default ``GEMINI_API_KEY`` / ``OPENAI_API_KEY``).
    temperature
        Sampling temperature.
    timeout
        Seconds per request.
    max_retries
        Retries after a failed attempt (timeouts, connection errors, HTTP 429 / 5xx).
    backoff
        First retry delay in seconds, doubled each retry.
    cache_dir
        Folder of cached responses (``<sha256>.json``); ``null`` disables caching.
    image, segmentation
        Reference image and instance segmentation (PNG); default: found next to the scene (module docstring).
    repair
        Apply the documented repairs (``false``: each is an error).
    fallback_confidence
        Confidence of ground edges added for objects the answer leaves unsupported.
    default_confidence
        Confidence of an edge that gives none.
    """

    provider: str = "gemini"
    model: str = "gemini-2.5-flash"
    base_url: str | None = None
    api_key_env: str | None = None
    temperature: float = 0.0
    timeout: float = 120.0
    max_retries: int = 3
    backoff: float = 2.0
    cache_dir: str | None = "results/cache/mllm"
    image: str | None = None
    segmentation: str | None = None
    repair: bool = True
    fallback_confidence: float = 0.1
    default_confidence: float = 0.5

    def __post_init__(self):
        if self.provider not in PROVIDERS:
            raise ValueError(f"topology.mllm.provider must be one of {list(PROVIDERS)}, got {self.provider!r}")
        if self.timeout <= 0 or self.max_retries < 0 or self.backoff < 0:
            raise ValueError("topology.mllm: timeout must be > 0, max_retries and backoff >= 0")


# -- request ---------------------------------------------------------------------------------------------------------
def object_metadata(scene) -> list[dict]:
    """Per-object metadata the prompt describes (world frame, metres, z up).

    Returns
    -------
    list of dict
        ``name``, ``description``, ``color`` (instance RGB, or null), ``aabb`` (``min``, ``max``),
        ``obb`` (``center``, ``extents``, ``rotation`` (3, 3) local-to-world axes as columns),
        ``footprint`` (``area`` in m^2 of the OBB projected onto the ground, ``polygon``: its 2D convex hull).
    """
    from scipy.spatial import ConvexHull

    out = []
    for o in scene.objects:
        m = o.world_mesh()
        obb = oriented_box(m)
        T = np.asarray(obb.primitive.transform)
        corners = np.asarray(obb.vertices)
        try:
            hull = corners[ConvexHull(corners[:, :2]).vertices, :2]
        except Exception:  # degenerate projection
            hull = corners[:, :2]
        r = lambda a: np.round(np.asarray(a, dtype=float), 4).tolist()  # noqa: E731
        out.append({"name": o.id, "description": o.description,
                    "color": list(o.color) if o.color is not None else None,
                    "aabb": {"min": r(m.bounds[0]), "max": r(m.bounds[1])},
                    "obb": {"center": r(T[:3, 3]), "extents": r(obb.primitive.extents), "rotation": r(T[:3, :3])},
                    "footprint": {"area": round(box_footprint_area(corners), 6), "polygon": r(hull)}})
    return out


#: Added to the user prompt of a scene with walls (:attr:`phiscene.scene.Scene.structure`), before its object list.
_WALL_PROMPT = """- The scene's walls are listed in the metadata ("walls": name, unit normal pointing into the room, and
  offset d: a point p lies on the wall where normal . p + d = 0). A wall supports what leans against it: add an
  edge wall_name -> object with relation "leans_on" (the object keeps its edge from the ground or the object it
  stands on). A wall is never supported. The wall names are:
"""


def user_prompt(names: list[str], walls: list[str] | None = None) -> str:
    """The paper's user prompt, its object list filled with ``names``; with ``walls`` (plane ids), the paragraph
    that names them as supporters (a scene without walls gets the paper's prompt unchanged)."""
    objects = "\n".join(f"- {n}" for n in names)
    if not walls:
        return _USER_PROMPT + objects
    head, tail = _USER_PROMPT.split("\nReturn strict JSON", 1)
    return (head + "\n" + _WALL_PROMPT + "\n".join(f"  - {w}" for w in walls) + "\n\nReturn strict JSON" + tail
            + objects)


@dataclass(frozen=True)
class Request:
    """Everything sent to the model (the API key aside)."""

    system: str
    user: str
    metadata: str
    image: bytes
    segmentation: bytes

    def text(self) -> str:
        """The user message text: prompt plus the metadata JSON."""
        return f"{self.user}\n\nScene metadata (JSON):\n{self.metadata}"

    def digest(self, params: MllmParams) -> str:
        """SHA-256 of the request and the settings that change the answer."""
        h = hashlib.sha256()
        for part in (params.provider, params.model, params.base_url or "", repr(float(params.temperature)),
                     self.system, self.user, self.metadata):
            h.update(part.encode())
            h.update(b"\0")
        h.update(hashlib.sha256(self.image).digest())
        h.update(hashlib.sha256(self.segmentation).digest())
        return h.hexdigest()


def reference_images(scene, params: MllmParams) -> tuple[Path, Path]:
    """Paths of the reference image and segmentation (module docstring).

    Raises
    ------
    PhisceneError
        When either cannot be found.
    """
    dirs = []
    if scene.camera is not None:
        dirs.append(Path(scene.camera).parent)
    if scene.source is not None:
        dirs += [Path(scene.source).parent.parent / "reference", Path(scene.source).parent / "reference"]
    found = []
    for name, given in (("image.png", params.image), ("segmentation.png", params.segmentation)):
        if given:
            if not Path(given).is_file():
                raise PhisceneError(f"{given}: file not found (topology.mllm.{name.split('.')[0]})")
            found.append(Path(given))
            continue
        hit = next((d / name for d in dirs if (d / name).is_file()), None)
        if hit is None:
            raise PhisceneError(f"{scene.source}: the mllm backend needs reference/{name} (searched "
                                f"{[str(d) for d in dirs]}; or set topology.mllm.{name.split('.')[0]})")
        found.append(hit)
    return found[0], found[1]


def build_request(scene, params: MllmParams) -> Request:
    """The request for ``scene``: prompts, metadata JSON and the two PNGs."""
    image, seg = reference_images(scene, params)
    data = {"objects": object_metadata(scene), "units": "m", "up": "+z"}
    walls = [p for p in scene.structure if p.kind == "wall"]
    if walls:
        data["walls"] = [{"name": p.id, "normal": [round(float(v), 6) for v in p.normal],
                          "offset": round(float(p.offset), 6)} for p in walls]
    meta = json.dumps(data, indent=1)
    return Request(SYSTEM_PROMPT, user_prompt(scene.ids, [p.id for p in walls]), meta, image.read_bytes(),
                   seg.read_bytes())


# -- providers -------------------------------------------------------------------------------------------------------
def _api_key(params: MllmParams) -> str:
    env = params.api_key_env or DEFAULT_KEY_ENV[params.provider]
    key = os.environ.get(env)
    if not key:
        raise MllmError(f"topology.mllm: environment variable {env} (the {params.provider} API key) is not set")
    return key


def _import(module: str):
    from importlib import import_module

    try:
        return import_module(module)
    except ImportError:
        raise MllmError(f"the mllm topology backend needs the '{module.split('.')[0]}' package: "
                        "pip install 'phiscene[mllm]'") from None


class _Retryable(Exception):
    """A transient failure worth another attempt."""


def call_openai(request: Request, params: MllmParams, api_key: str) -> str:
    """One chat-completions request through the ``openai`` client; returns the message text."""
    openai = _import("openai")
    client = openai.OpenAI(api_key=api_key, base_url=params.base_url, timeout=params.timeout, max_retries=0)

    def data_url(png: bytes) -> str:
        return "data:image/png;base64," + base64.b64encode(png).decode()

    messages = [{"role": "system", "content": request.system},
                {"role": "user", "content": [
                    {"type": "image_url", "image_url": {"url": data_url(request.image)}},
                    {"type": "image_url", "image_url": {"url": data_url(request.segmentation)}},
                    {"type": "text", "text": request.text()}]}]
    try:
        resp = client.chat.completions.create(model=params.model, messages=messages, temperature=params.temperature,
                                              response_format={"type": "json_object"})
    except (openai.APITimeoutError, openai.APIConnectionError, openai.RateLimitError,
            openai.InternalServerError) as exc:
        raise _Retryable(f"{type(exc).__name__}: {exc}") from None
    except openai.APIStatusError as exc:
        raise MllmError(f"openai endpoint refused the request: HTTP {exc.status_code}") from None
    if not resp.choices or resp.choices[0].message.content is None:
        raise MllmResponseError("openai endpoint returned no message content")
    return resp.choices[0].message.content


def call_gemini(request: Request, params: MllmParams, api_key: str) -> str:
    """One ``generate_content`` request through ``google-genai``; returns the response text."""
    genai = _import("google.genai")
    from google.genai import errors, types

    http = types.HttpOptions(timeout=int(params.timeout * 1000), base_url=params.base_url,
                             retry_options=types.HttpRetryOptions(attempts=1))
    client = genai.Client(api_key=api_key, http_options=http)
    config = types.GenerateContentConfig(system_instruction=request.system, temperature=params.temperature,
                                         response_mime_type="application/json")
    contents = [types.Part.from_bytes(data=request.image, mime_type="image/png"),
                types.Part.from_bytes(data=request.segmentation, mime_type="image/png"), request.text()]
    try:
        resp = client.models.generate_content(model=params.model, contents=contents, config=config)
    except errors.APIError as exc:
        if exc.code == 429 or (exc.code or 0) >= 500:
            raise _Retryable(f"HTTP {exc.code}") from None
        raise MllmError(f"gemini refused the request: HTTP {exc.code}") from None
    except Exception as exc:  # httpx timeouts / connection errors surface as their own types
        if "timeout" in type(exc).__name__.lower() or "connect" in type(exc).__name__.lower():
            raise _Retryable(f"{type(exc).__name__}") from None
        raise
    if not resp.text:
        raise MllmResponseError("gemini returned no text")
    return resp.text


PROVIDER_CALLS = {"gemini": call_gemini, "openai": call_openai}


def ask(request: Request, params: MllmParams) -> tuple[str, str, bool]:
    """The model's answer to ``request``: from the cache, else from the provider with retries.

    Returns
    -------
    text
        The raw response text.
    digest
        The request hash (cache key).
    cached
        Whether it came from the cache.
    """
    digest = request.digest(params)
    cache = Path(params.cache_dir) / f"{digest}.json" if params.cache_dir else None
    if cache is not None and cache.is_file():
        try:
            entry = json.loads(cache.read_text())
            if not isinstance(entry, dict) or not isinstance(entry.get("response"), str):
                raise ValueError("no 'response' text")
            return entry["response"], digest, True
        except (ValueError, UnicodeDecodeError) as exc:  # a damaged entry is asked again, then overwritten
            log.warning("mllm: cache entry %s is unreadable (%s); asking the model again", cache, exc)
    key = _api_key(params)
    call = PROVIDER_CALLS[params.provider]
    last = ""
    for attempt in range(params.max_retries + 1):
        if attempt:
            delay = params.backoff * 2 ** (attempt - 1)
            log.warning("mllm: attempt %d failed (%s); retrying in %.1f s", attempt, last, delay)
            time.sleep(delay)
        try:
            text = call(request, params, key)
            break
        except _Retryable as exc:
            last = str(exc).replace(key, "***")
    else:
        raise MllmError(f"{params.provider} model {params.model}: no answer after {params.max_retries + 1} attempts "
                        f"(last: {last}; timeout {params.timeout} s)")
    if cache is not None:
        write_text(cache, json.dumps({"provider": params.provider, "model": params.model, "request": digest,
                                      "response": text}, indent=1) + "\n")
    return text, digest, False


# -- parsing ---------------------------------------------------------------------------------------------------------
def _json_object(text: str) -> dict:
    """The JSON object in ``text``: the whole text, else the span from the first '{' to the last '}'."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        start, end = text.find("{"), text.rfind("}")
        if start < 0 or end <= start:
            raise MllmResponseError(
                f"response is not JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
        try:
            data = json.loads(text[start:end + 1])
        except json.JSONDecodeError as exc2:
            raise MllmResponseError(f"response is not valid JSON ({exc2.msg} at line {exc2.lineno} "
                                    f"column {exc2.colno})") from None
        data = {"__repaired__": True, **data} if isinstance(data, dict) else data
    if not isinstance(data, dict):
        raise MllmResponseError(f"response JSON must be an object, got {type(data).__name__}")
    return data


def parse_response(text: str, ids: list[str], repair: bool = True, fallback_confidence: float = 0.1,
                   default_confidence: float = 0.5, walls: list[str] | None = None) -> tuple[list[SupportEdge], list[str]]:
    """Validate a model answer against the scene's object ids (module docstring for the rules).

    Parameters
    ----------
    text
        The raw response.
    ids
        The scene's object ids.
    repair
        Apply the documented repairs; ``False`` makes each an error.
    walls
        The scene's wall ids: valid supporters (an edge into one is dropped, a repair).

    Returns
    -------
    edges
        Valid edges, every object supported by at least one.
    repairs
        One line per repair applied.

    Raises
    ------
    MllmResponseError
        Unparseable or wrongly shaped JSON, bad confidences, or (``repair=False``) anything needing repair.
    """
    repairs: list[str] = []

    def fix(msg: str) -> None:
        if not repair:
            raise MllmResponseError(msg)
        repairs.append(msg)

    data = _json_object(text)
    if data.pop("__repaired__", False):
        fix("stripped text around the JSON object")
    edges_in = data.get("edges")
    if not isinstance(edges_in, list):
        raise MllmResponseError("response has no 'edges' list")
    planes = set(walls or ())
    lower = {i.lower(): i for i in [*ids, *planes]}

    def node(name, where: str) -> str | None:
        if not isinstance(name, str):
            raise MllmResponseError(f"{where}: expected a string, got {name!r}")
        if name in ids or name in planes:
            return name
        if name.strip().lower() in GROUND_ALIASES:
            if name not in (GROUND, "Plane"):  # "Plane" is the prompt schema's own name for the ground
                fix(f"{where}: {name!r} read as the ground")
            return GROUND
        if name.strip().lower() in lower:
            fix(f"{where}: {name!r} matched to {lower[name.strip().lower()]!r} ignoring case")
            return lower[name.strip().lower()]
        fix(f"{where}: unknown object {name!r}; edge dropped")
        return None

    kept: dict[tuple[str, str], SupportEdge] = {}
    for i, e in enumerate(edges_in):
        where = f"edges[{i}]"
        if not isinstance(e, dict):
            raise MllmResponseError(f"{where}: expected an object, got {e!r}")
        src, dst = node(e.get("from"), f"{where}.from"), node(e.get("to"), f"{where}.to")
        conf = e.get("confidence")
        if conf is None:
            fix(f"{where}: no confidence; using {default_confidence}")
            conf = default_confidence
        if isinstance(conf, bool) or not isinstance(conf, (int, float)) or not 0.0 <= conf <= 1.0:
            raise MllmResponseError(f"{where}.confidence: expected a number in [0, 1], got {conf!r}")
        if src is None or dst is None:
            continue
        if dst == GROUND or dst in planes:
            fix(f"{where}: an edge into the ground or a wall ({src} -> {dst}); dropped")
            continue
        if src == dst:
            fix(f"{where}: self loop on {src!r}; dropped")
            continue
        relation = e.get("relation", "supports")
        if relation not in RELATIONS:
            fix(f"{where}.relation: {relation!r} read as 'supports'")
            relation = "supports"
        edge = SupportEdge(src, dst, relation, float(conf), str(e.get("reason", ""))[:500])
        if (src, dst) in kept:
            fix(f"{where}: duplicate edge {src} -> {dst}; the more confident one kept")
            if kept[(src, dst)].confidence >= edge.confidence:
                continue
        kept[(src, dst)] = edge
    edges = list(kept.values())
    supported = {e.target for e in edges}
    for oid in ids:
        if oid not in supported:
            fix(f"object {oid!r} has no supporter; added ground -> {oid} (confidence {fallback_confidence})")
            edges.append(SupportEdge(GROUND, oid, "supports", fallback_confidence,
                                     "not in the answer: assumed on the ground"))
    return edges, repairs


def infer(scene, params: MllmParams = MllmParams()) -> SupportGraph:
    """Support graph and placement order of ``scene`` from the configured MLLM.

    Raises
    ------
    MllmError
        Missing package or key, or no answer after the retries.
    MllmResponseError
        An unusable answer (the message names the cached response file when there is one).
    """
    request = build_request(scene, params)
    text, digest, cached = ask(request, params)
    walls = [p.id for p in scene.structure if p.kind == "wall"]
    try:
        edges, repairs = parse_response(text, scene.ids, params.repair, params.fallback_confidence,
                                        params.default_confidence, walls)
    except MllmResponseError as exc:
        where = Path(params.cache_dir) / f"{digest}.json" if params.cache_dir else "response"
        raise MllmResponseError(f"{where}: {exc}") from None
    for r in repairs:
        log.warning("mllm: repaired: %s", r)
    graph = SupportGraph(objects=scene.ids, edges=edges, backend="mllm",
                         meta={"provider": params.provider, "model": params.model, "request": digest,
                               "cached": cached, "repairs": repairs},
                         structure=[w for w in walls if any(e.source == w for e in edges)])
    check_graph(graph, None, scene.ids)
    return finalize(graph, scene=scene)
