"""The on-disk cache of derived models: reuse, invalidation, agreement with a fresh derivation."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from equilibrist.numeric import cache
from equilibrist.systems import registry


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("EQUILIBRIST_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "_MEMO", {})
    return tmp_path


def test_second_load_reads_the_cache_without_deriving(fresh_cache, monkeypatch) -> None:
    entry = registry.lookup("cartpole")
    first = cache.load(entry)
    files = sorted(p.name for p in fresh_cache.iterdir())
    assert any(f.endswith(".py") for f in files) and any(f.endswith(".pkl") for f in files)

    monkeypatch.setattr(cache, "_MEMO", {})

    def refuse(_entry):
        raise AssertionError("derived again although the cache was valid")

    monkeypatch.setattr(cache, "derive", refuse)
    second = cache.load(entry)
    assert second.key == first.key
    x, u = np.array([0.1, 0.2, -0.3, 0.4]), np.array([1.5])
    out1, out2 = np.empty(4), np.empty(4)
    first.functions.f(x, u, np.array([10, 1, 0.5, 0.08333, 0.1, 0.2, 9.8, -1, 1.0]), out1)
    second.functions.f(x, u, np.array([10, 1, 0.5, 0.08333, 0.1, 0.2, 9.8, -1, 1.0]), out2)
    assert np.array_equal(out1, out2)


def test_changed_model_source_changes_the_key(fresh_cache, monkeypatch) -> None:
    entry = registry.lookup("cartpole")
    key = cache.model_key(entry)
    original = cache._source_of

    def edited(name: str) -> bytes:
        data = original(name)
        return data + b"\n# edited\n" if name == entry.module else data

    monkeypatch.setattr(cache, "_source_of", edited)
    assert cache.model_key(entry) != key
    calls = []
    real_derive = cache.derive

    def counting(e):
        calls.append(e.spec.key)
        return real_derive(e)

    monkeypatch.setattr(cache, "derive", counting)
    cache.load(entry)
    assert calls == ["cartpole"]


def test_cached_symbolic_model_equals_a_fresh_derivation(fresh_cache) -> None:
    entry = registry.lookup("cartpole")
    cached = cache.load(entry).symbolic
    fresh = cache.derive(entry)
    diff = (cached.f - fresh.f).applyfunc(sp.simplify)
    assert diff == sp.zeros(*diff.shape)
    assert (cached.A - fresh.A).applyfunc(sp.simplify) == sp.zeros(*cached.A.shape)
