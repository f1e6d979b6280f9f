"""``mllm`` topology backend against a fake model server on 127.0.0.1 (started here; no other network)."""

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest
import trimesh
from PIL import Image

pytest.importorskip("openai")  # optional extra `mllm` (also in `test`)
pytest.importorskip("google.genai")

from phiscene import topology
from phiscene.meshes import save_mesh
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.topology.mllm import SYSTEM_PROMPT, MllmError, MllmResponseError, parse_response
from phiscene.transforms import make_pose

KEY = "sk-test-secret-123"


class FakeModel(BaseHTTPRequestHandler):
    """Answers OpenAI chat completions and Gemini generateContent with the next queued (delay, text)."""

    answers: list = []
    seen: list = []

    def do_POST(self):  # noqa: N802 (http.server API)
        body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
        FakeModel.seen.append({"path": self.path, "headers": {k.lower(): v for k, v in self.headers.items()},
                               "body": body})
        delay, text = FakeModel.answers.pop(0) if len(FakeModel.answers) > 1 else FakeModel.answers[0]
        time.sleep(delay)
        if "generateContent" in self.path:
            out = {"candidates": [{"content": {"role": "model", "parts": [{"text": text}]}, "finishReason": "STOP",
                                   "index": 0}]}
        else:
            out = {"id": "c1", "object": "chat.completion", "created": 0, "model": body["model"],
                   "choices": [{"index": 0, "finish_reason": "stop",
                                "message": {"role": "assistant", "content": text}}]}
        data = json.dumps(out).encode()
        try:
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)
        except (BrokenPipeError, ConnectionResetError):  # the client gave up (timeout test)
            pass

    def log_message(self, *args):
        pass


@pytest.fixture
def server(monkeypatch):
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")
    monkeypatch.setenv("no_proxy", "127.0.0.1,localhost")
    monkeypatch.setenv("PHI_TEST_KEY", KEY)
    FakeModel.answers, FakeModel.seen = [], []
    srv = ThreadingHTTPServer(("127.0.0.1", 0), FakeModel)
    srv.daemon_threads = True
    t = threading.Thread(target=srv.serve_forever, daemon=True)
    t.start()
    yield f"http://127.0.0.1:{srv.server_address[1]}"
    srv.shutdown()
    srv.server_close()


@pytest.fixture
def scene(tmp_path):
    """base (0.4 x 0.4 box) on the ground, cube on base, side box on the ground; reference PNGs beside."""
    objs = []
    for oid, size, xyz in (("base", (0.4, 0.4, 0.2), (0, 0, 0.1)), ("cube", (0.1, 0.1, 0.1), (0, 0, 0.25)),
                           ("side", (0.2, 0.2, 0.2), (0.6, 0, 0.1))):
        path = save_mesh(trimesh.creation.box(size), tmp_path / f"s/initial/meshes/{oid}.glb")
        objs.append(SceneObject(oid, path, make_pose(translation=xyz), f"a {oid} box", (len(objs) * 60 + 40, 10, 10)))
    save_scene(Scene(objs), tmp_path / "s/initial/scene.json")
    (tmp_path / "s/reference").mkdir()
    Image.fromarray(np.full((8, 8, 3), 128, np.uint8)).save(tmp_path / "s/reference/image.png")
    Image.fromarray(np.full((8, 8, 3), 40, np.uint8)).save(tmp_path / "s/reference/segmentation.png")
    return load_scene(tmp_path / "s/initial/scene.json")


def answer(edges, objects=("Plane", "base", "cube", "side")):
    return json.dumps({"objects": list(objects), "edges": [
        {"from": a, "to": b, "relation": "supports", "confidence": c, "reason": "r"} for a, b, c in edges]})


VALID = answer([("Plane", "base", 0.95), ("base", "cube", 0.9), ("Plane", "side", 0.8)])


def settings(url, tmp_path, provider="openai", **kw):
    return {"provider": provider, "model": "fake-model", "base_url": url + ("/v1" if provider == "openai" else ""),
            "api_key_env": "PHI_TEST_KEY", "cache_dir": str(tmp_path / "cache"), "timeout": 5, "max_retries": 0,
            "backoff": 0.01, **kw}


def test_valid_answer_openai_and_cache(server, scene, tmp_path, caplog):
    FakeModel.answers = [(0, VALID)]
    caplog.set_level("DEBUG")
    g = topology.infer(scene, "mllm", settings(server, tmp_path))
    assert g.pairs() == {("ground", "base"), ("base", "cube"), ("ground", "side")}
    assert g.order.index("base") < g.order.index("cube") and g.meta["repairs"] == []
    req = FakeModel.seen[0]
    assert req["path"] == "/v1/chat/completions"
    assert req["headers"]["authorization"] == f"Bearer {KEY}"
    msgs = req["body"]["messages"]
    assert msgs[0] == {"role": "system", "content": SYSTEM_PROMPT}
    content = msgs[1]["content"]
    assert [c["type"] for c in content] == ["image_url", "image_url", "text"]
    assert content[0]["image_url"]["url"].startswith("data:image/png;base64,")
    text = content[2]["text"]
    assert "Object list (every name below must appear in \"objects\"):\n- base\n- cube\n- side" in text
    meta = json.loads(text.split("Scene metadata (JSON):\n", 1)[1])
    base = meta["objects"][0]
    assert base["name"] == "base" and base["color"] == [40, 10, 10]
    np.testing.assert_allclose(base["aabb"]["min"], [-0.2, -0.2, 0.0], atol=1e-4)
    np.testing.assert_allclose(base["footprint"]["area"], 0.16, atol=1e-6)  # 0.4 x 0.4 box seen from above
    np.testing.assert_allclose(sorted(base["obb"]["extents"]), [0.2, 0.4, 0.4], atol=1e-4)
    # rerun: served from the cache, nothing sent
    g2 = topology.infer(scene, "mllm", settings(server, tmp_path))
    assert len(FakeModel.seen) == 1 and g2.meta["cached"] and g2.pairs() == g.pairs()
    cached = list((tmp_path / "cache").glob("*.json"))
    assert len(cached) == 1 and KEY not in cached[0].read_text()
    assert KEY not in caplog.text


def test_valid_answer_gemini_over_loopback(server, scene, tmp_path):
    FakeModel.answers = [(0, VALID)]
    g = topology.infer(scene, "mllm", settings(server, tmp_path, provider="gemini"))
    assert g.pairs() == {("ground", "base"), ("base", "cube"), ("ground", "side")}
    req = FakeModel.seen[0]
    assert req["path"].endswith("/models/fake-model:generateContent")
    assert req["headers"].get("x-goog-api-key") == KEY
    body = req["body"]
    assert body["systemInstruction"]["parts"][0]["text"] == SYSTEM_PROMPT
    parts = body["contents"][0]["parts"]
    inline = [p.get("inlineData", p.get("inline_data", {})) for p in parts[:2]]
    assert [d.get("mimeType", d.get("mime_type")) for d in inline] == ["image/png", "image/png"]
    assert "- side" in parts[2]["text"]
    assert body["generationConfig"]["responseMimeType"] == "application/json"


def test_malformed_json_is_a_clear_error_and_fences_are_repaired(server, scene, tmp_path):
    FakeModel.answers = [(0, '{"edges": [{"from": "Plane", "to": "base",')]
    with pytest.raises(MllmResponseError, match=r"cache/[0-9a-f]{64}\.json: response is not"):
        topology.infer(scene, "mllm", settings(server, tmp_path))
    edges, repairs = parse_response("Here you go:\n```json\n" + VALID + "\n```", ["base", "cube", "side"])
    assert {e.pair for e in edges} == {("ground", "base"), ("base", "cube"), ("ground", "side")}
    assert repairs[0] == "stripped text around the JSON object"
    with pytest.raises(MllmResponseError, match="confidence: expected a number in \\[0, 1\\], got 1.5"):
        parse_response(answer([("Plane", "base", 1.5)]), ["base"])


def test_unknown_names(server, scene, tmp_path):
    FakeModel.answers = [(0, answer([("Plane", "base", 0.9), ("table", "cube", 0.9), ("Plane", "side", 0.9),
                                     ("BASE", "cube", 0.6)]))]
    g = topology.infer(scene, "mllm", settings(server, tmp_path))
    assert g.pairs() == {("ground", "base"), ("base", "cube"), ("ground", "side")}
    assert any("unknown object 'table'" in r for r in g.meta["repairs"])
    with pytest.raises(MllmResponseError, match="unknown object 'table'"):
        topology.infer(scene, "mllm", settings(server, tmp_path, repair=False))


def test_missing_objects_get_a_low_confidence_ground_edge(server, scene, tmp_path):
    FakeModel.answers = [(0, answer([("Plane", "base", 0.9), ("base", "cube", 0.9)], ("Plane", "base", "cube")))]
    g = topology.infer(scene, "mllm", settings(server, tmp_path, fallback_confidence=0.05))
    side = [e for e in g.edges if e.target == "side"]
    assert [(e.source, e.confidence) for e in side] == [("ground", 0.05)]
    assert sorted(g.order) == ["base", "cube", "side"]
    with pytest.raises(MllmResponseError, match="object 'side' has no supporter"):
        topology.infer(scene, "mllm", settings(server, tmp_path, repair=False))


def test_cycle_is_broken_at_the_lowest_confidence(server, scene, tmp_path):
    FakeModel.answers = [(0, answer([("Plane", "base", 0.9), ("base", "cube", 0.8), ("cube", "side", 0.7),
                                     ("side", "base", 0.3), ("Plane", "side", 0.6)]))]
    g = topology.infer(scene, "mllm", settings(server, tmp_path))
    assert [e.pair for e in g.dropped_edges] == [("side", "base")]
    assert g.order == ["base", "cube", "side"]


def test_timeout_retries_with_backoff_then_fails(server, scene, tmp_path):
    FakeModel.answers = [(1.5, VALID)]
    t0 = time.perf_counter()
    with pytest.raises(MllmError, match="no answer after 2 attempts"):
        topology.infer(scene, "mllm", settings(server, tmp_path, timeout=0.3, max_retries=1, backoff=0.05))
    assert time.perf_counter() - t0 < 1.4  # two 0.3 s attempts and one 0.05 s pause, not the server's 1.5 s
    assert len(FakeModel.seen) == 2
    assert not list((tmp_path / "cache").glob("*.json"))  # failures are not cached


def test_missing_key_is_a_clear_error(server, scene, tmp_path, monkeypatch):
    monkeypatch.delenv("PHI_TEST_KEY")
    with pytest.raises(MllmError, match="environment variable PHI_TEST_KEY"):
        topology.infer(scene, "mllm", settings(server, tmp_path))
    assert FakeModel.seen == []


def test_damaged_cache_entry_is_asked_again_and_overwritten(server, scene, tmp_path):
    FakeModel.answers = [(0, VALID), (0, VALID)]
    g = topology.infer(scene, "mllm", settings(server, tmp_path))
    (entry,) = (tmp_path / "cache").glob("*.json")
    entry.write_text('{"response": ')  # truncated by a crash
    g2 = topology.infer(scene, "mllm", settings(server, tmp_path))
    assert len(FakeModel.seen) == 2 and not g2.meta["cached"] and g2.pairs() == g.pairs()
    assert json.loads(entry.read_text())["response"]  # rewritten whole


def test_unreachable_endpoint_fails_the_job_not_the_scene():
    from phiscene.topology.mllm import MllmError, MllmResponseError

    # an unreachable service is a setup problem (the job fails); a bad answer is about this scene
    assert MllmError("x").per_scene is False and MllmResponseError("x").per_scene is True


def test_walls_are_named_in_the_prompt_and_kept_as_supporters(server, scene, tmp_path):
    # the side box against the wall x = 0.7 (normal -x): the answer's wall edge is kept, one into the wall dropped
    from dataclasses import replace

    from phiscene.scene import Plane

    walled = replace(scene, structure=[Plane("wall_0", "wall", (-1.0, 0.0, 0.0), 0.7, estimated=True)])
    FakeModel.answers = [(0, json.dumps({"objects": ["Plane", "base", "cube", "side", "wall_0"], "edges": [
        {"from": "Plane", "to": "base", "confidence": 0.9}, {"from": "base", "to": "cube", "confidence": 0.9},
        {"from": "Plane", "to": "side", "confidence": 0.9},
        {"from": "wall_0", "to": "side", "relation": "leans_on", "confidence": 0.7},
        {"from": "side", "to": "wall_0", "confidence": 0.2}]}))]
    g = topology.infer(walled, "mllm", settings(server, tmp_path))
    assert g.parents("side") == ["ground", "wall_0"] and g.structure == ["wall_0"]
    assert any("into the ground or a wall (side -> wall_0)" in r for r in g.meta["repairs"])
    text = FakeModel.seen[0]["body"]["messages"][1]["content"][2]["text"]
    assert "The wall names are:\n  - wall_0\n" in text and text.index("wall_0") < text.index("Object list")
    meta = json.loads(text.split("Scene metadata (JSON):\n", 1)[1])
    assert meta["walls"] == [{"name": "wall_0", "normal": [-1.0, 0.0, 0.0], "offset": 0.7}]
    # a scene without walls gets the paper's prompt: nothing about walls
    FakeModel.answers = [(0, VALID)]
    topology.infer(scene, "mllm", settings(server, tmp_path / "other"))
    plain = FakeModel.seen[1]["body"]["messages"][1]["content"][2]["text"]
    assert "wall_0" not in plain and "The wall names" not in plain and '"walls"' not in plain

