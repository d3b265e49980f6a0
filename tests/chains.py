"""Random serial chains as URDF text, with the degenerate cases put in on purpose."""

from __future__ import annotations

import numpy as np

CASES = ("general", "parallel", "intersecting", "coincident", "prismatic", "gimbal", "fixed")


def _fmt(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def _unit(v):
    return v / np.linalg.norm(v)


def random_chain(rng: np.random.Generator, n: int | None = None, cases=CASES) -> tuple[str, list[str]]:
    """URDF text of a random chain base_link -> tip, and the case used at each joint.

    Each joint i > 1 takes a case relative to joint i-1: general position, parallel
    axis, intersecting axes, coincident axes, a prismatic joint, an origin with pitch
    near +-90 deg, or a fixed joint inserted before it. Joint 1 is in general position
    relative to the base.
    """
    n = int(rng.integers(3, 8)) if n is None else n
    lines = ['<?xml version="1.0"?>', "<!-- random chain made by kincal's tests -->",
             '<robot name="random_chain">', '  <link name="base_link"/>']
    parent, used = _branch(rng, lines, "base_link", "", n, cases)
    _tip(rng, lines, parent, "")
    lines += ["</robot>", ""]
    return "\n".join(lines), used


def random_tree(rng: np.random.Generator, cases=CASES) -> tuple[str, dict[str, list[str]]]:
    """URDF text of a random tree, and the joint names of each branch.

    base_link carries a trunk ``t`` (2 joints) whose last link carries two branches ``a``
    and ``b``; base_link also carries a branch ``c``. Each branch has 2-5 joints with the
    cases of :func:`random_chain`, joint 2 of branch ``a`` and of ``c`` always prismatic,
    and ends in a fixed frame ``<branch>tip``. A base at ``atip`` and a tip at ``btip``
    climb branch a (reversed revolute and prismatic joints) and go down branch b.
    """
    lines = ['<?xml version="1.0"?>', "<!-- random tree made by kincal's tests -->",
             '<robot name="random_tree">', '  <link name="base_link"/>']
    joints = {}
    trunk, _ = _branch(rng, lines, "base_link", "t", 2, cases)
    joints["t"] = ["tj1", "tj2"]
    for prefix, parent in (("a", trunk), ("b", trunk), ("c", "base_link")):
        n = int(rng.integers(2, 6))
        last, _ = _branch(rng, lines, parent, prefix, n, cases,
                          prismatic_at=2 if prefix in "ac" else None)
        joints[prefix] = [f"{prefix}j{i}" for i in range(1, n + 1)]
        _tip(rng, lines, last, prefix)
    lines += ["</robot>", ""]
    return "\n".join(lines), joints


def _tip(rng, lines, parent, prefix):
    tip_xyz = rng.uniform(-0.2, 0.2, 3)
    lines += [f'  <joint name="{prefix}tip_joint" type="fixed">', f'    <parent link="{parent}"/>',
              f'    <child link="{prefix}tip"/>',
              f'    <origin xyz="{_fmt(tip_xyz)}" rpy="0.1 0.2 0.3"/>', "  </joint>",
              f'  <link name="{prefix}tip"/>']


def _branch(rng, lines, parent, prefix, n, cases, prismatic_at=None):
    """Append n random joints below ``parent`` to ``lines``; (last link, cases used)."""
    prev_axis = _unit(rng.normal(size=3))
    used = []
    for i in range(1, n + 1):
        case = "general" if i == 1 else str(rng.choice(cases))
        if i == prismatic_at:
            case = "prismatic"
        used.append(case)
        axis = _unit(rng.normal(size=3)) if rng.random() < 0.6 else np.eye(3)[rng.integers(3)]
        xyz = rng.uniform(-0.3, 0.3, 3)
        rpy = rng.uniform(-np.pi, np.pi, 3)
        kind = "revolute" if rng.random() < 0.8 else "continuous"
        if case == "fixed":
            lines += [f'  <joint name="{prefix}fixed_{i}" type="fixed">', f'    <parent link="{parent}"/>',
                      f'    <child link="{prefix}fixed_link_{i}"/>',
                      f'    <origin xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"/>', "  </joint>",
                      f'  <link name="{prefix}fixed_link_{i}"/>']
            parent = f"{prefix}fixed_link_{i}"
            xyz = rng.uniform(-0.3, 0.3, 3)
            rpy = rng.uniform(-np.pi, np.pi, 3)
        elif case == "parallel":
            rpy, axis = np.zeros(3), prev_axis
        elif case == "intersecting":
            xyz = prev_axis * rng.uniform(-0.3, 0.3)
        elif case == "coincident":
            xyz, rpy, axis = prev_axis * rng.uniform(-0.3, 0.3), np.zeros(3), prev_axis
        elif case == "prismatic":
            kind = "prismatic"
        elif case == "gimbal":
            rpy[1] = np.pi / 2 * rng.choice([-1.0, 1.0]) + rng.normal() * 1e-7
        limit = ('    <limit lower="-0.3" upper="0.3" effort="1" velocity="1"/>' if kind == "prismatic"
                 else '    <limit lower="-3.0" upper="3.0" effort="1" velocity="1"/>')
        lines += [f'  <joint name="{prefix}j{i}" type="{kind}">', f'    <parent link="{parent}"/>',
                  f'    <child link="{prefix}l{i}"/>', f'    <origin xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"/>',
                  f'    <axis xyz="{_fmt(axis)}"/>']
        if kind != "continuous":
            lines.append(limit)
        lines += ["  </joint>", f'  <link name="{prefix}l{i}"/>']
        parent = f"{prefix}l{i}"
        prev_axis = axis
    return parent, used


def sample_robots(tmp_path, named=("ec66",)):
    """Robots of every shape the fast paths must match: the named ones, two random chains
    (prismatic, parallel, gimbal and general joints) and a tree path (base on one branch,
    tip on another), their URDFs written under ``tmp_path``."""
    from kincal.robot import Robot

    out = [Robot.load(name) for name in named]
    for seed in (3, 4):
        text, _ = random_chain(np.random.default_rng(seed), cases=("prismatic", "parallel",
                                                                   "gimbal", "general"))
        path = tmp_path / f"chain_{seed}.urdf"
        path.write_text(text)
        out.append(Robot.load(path, tip="tip"))
    text, _ = random_tree(np.random.default_rng(5))
    path = tmp_path / "tree.urdf"
    path.write_text(text)
    out.append(Robot.load(path, base="atip", tip="btip"))
    return out
