"""The shared parameter-dataclass base :class:`phiscene.params.Params`."""

from dataclasses import dataclass, field

import pytest

from phiscene.assembly.assemble import AssemblyParams
from phiscene.assembly.penetration import PenetrationParams
from phiscene.params import Params
from phiscene.sdf_grid import GridParams
from phiscene.topology.geometric import GeometricParams
from phiscene.topology.params import BackendParams


@dataclass(frozen=True)
class _Inner(Params):
    _label = "inner parameters"
    k: int = 1

    def check(self) -> None:
        if self.k < 1:
            raise ValueError(f"inner k must be >= 1, got {self.k}")


@dataclass(frozen=True)
class _Outer(Params):
    _coerce = {"pair": lambda v: tuple(int(x) for x in v)}
    pair: tuple = (1, 2)
    inner: _Inner = field(default_factory=_Inner)


def test_unknown_keys_name_label_and_known_keys():
    with pytest.raises(ValueError, match=r"^unknown inner parameters \['a', 'b'\]; known: \['k'\]$"):
        _Inner.from_dict({"b": 0, "a": 0, "k": 2})
    # no label: the class name
    with pytest.raises(ValueError, match=r"^unknown _Outer keys \['x'\]; known: \['inner', 'pair'\]$"):
        _Outer.from_dict({"x": 1})


def test_nested_coerce_check_and_round_trip():
    p = _Outer.from_dict({"pair": ["3", 4.0], "inner": {"k": 5}})
    assert p == _Outer(pair=(3, 4), inner=_Inner(k=5))
    assert p.to_dict() == {"pair": (3, 4), "inner": {"k": 5}}
    assert _Outer.from_dict(p.to_dict()) == p
    assert _Outer.from_dict(None) == _Outer() == _Outer.from_dict({"inner": None})
    inner = _Inner(k=7)
    assert _Outer.from_dict({"inner": inner}).inner is inner
    with pytest.raises(ValueError, match="inner k must be >= 1, got 0"):
        _Outer.from_dict({"inner": {"k": 0}})
    with pytest.raises(ValueError, match="unknown inner parameters"):
        _Outer.from_dict({"inner": {"q": 0}})
    with pytest.raises(ValueError, match=r"_Outer.inner must be a mapping of _Inner fields, got 'x'"):
        _Outer.from_dict({"inner": "x"})


def test_ported_classes_keep_their_parsing():
    assert BackendParams is Params and issubclass(GeometricParams, Params)
    a = AssemblyParams.from_dict({"penetration_params": {"eps": 0.01, "grid": {"resolution": 32}}})
    assert a.penetration_params.eps == 0.01 and a.penetration_params.grid == GridParams(resolution=32)
    assert AssemblyParams.from_dict(a.to_dict()) == a
    with pytest.raises(ValueError, match="unknown SDF grid parameters"):
        PenetrationParams.from_dict({"grid": {"bogus": 1}})
    with pytest.raises(ValueError, match="penetration eps must be >= 0"):
        AssemblyParams.from_dict({"penetration_params": {"eps": -1.0}})
    with pytest.raises(ValueError, match="assembly parameter 'settle' must be true or false"):
        AssemblyParams.from_dict({"settle": 1})
