"""Per-element muscle lines of the appendix A shoulder from the public DAS3 OpenSim model.

``robots/shoulder_muscles.json`` lumps each muscle's DAS3 elements into one line (force-weighted
attachment points). The lumped line can lose much of the elements' moment arm (the
middle deltoid's 6.9 mm of abduction arm at neutral against 11.4 mm for its
seven elements). This module reads the elements themselves from DAS3's ``das4_v4.osim``
(Chadwick et al. 2014; repository ``AbdnBiomechEng/arm-model``, MIT licence) and writes
``robots/shoulder_elements.json``, from which :func:`qpcoord.robots.shoulder.build` makes
per-element lines (``lines="elements"``).

Procedure (:func:`read_elements`): the thorax → clavicle → scapula → humerus chain of
``CustomJoint`` s is evaluated at the model's default coordinates (offset frames with
body-fixed X-Y-Z orientations, ``SpatialTransform`` rotations applied in order about their
axes, translations along theirs); each element's first path point is taken to the thorax
frame and centred on the glenohumeral (GH) centre (the origin of ``humerus_r``), its first
path point on ``humerus_r`` (where the line reaches the humerus; later humeral points are
fixed to the humerus and carry no moment about the GH centre) is kept in ``humerus_r``
coordinates; both are mapped from DAS3's axes (X lateral, Y up, Z posterior) to ISB axes
(X anterior, Y superior, Z lateral). For the eleven muscles no element has a via point off
the humerus (``via_points``; 3 subscapularis elements have a second humeral point,
``humerus_points``). The lumped origins and insertions of ``shared/data/shoulder-muscles.md``
are the force-weighted means of these points to its millimetre rounding (tested).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

__all__ = ["DAS3_MUSCLES", "DAS_TO_ISB", "read_elements"]

#: DAS3 elements of each of the thesis's eleven muscles (the data note's grouping).
DAS3_MUSCLES: dict[str, tuple[str, ...]] = {
    "deltoideus posterior": tuple(f"delt_scap_{k}" for k in range(1, 5)),
    "deltoideus medial": (*(f"delt_scap_{k}" for k in range(5, 10)), "delt_scap10", "delt_scap11"),
    "deltoideus anterior": tuple(f"delt_clav_{k}" for k in range(1, 5)),
    "coracobrachialis": tuple(f"coracobr_{k}" for k in range(1, 4)),
    "infraspinatus": tuple(f"infra_{k}" for k in range(1, 7)),
    "teres minor": tuple(f"ter_min_{k}" for k in range(1, 4)),
    "teres major": tuple(f"ter_maj_{k}" for k in range(1, 5)),
    "supraspinatus": tuple(f"supra_{k}" for k in range(1, 5)),
    "subscapularis": (*(f"subscap_{k}" for k in range(1, 10)), "subscap10", "subscap11"),
    "latissimus dorsi": tuple(f"lat_dorsi_{k}" for k in range(1, 7)),
    "pectoralis major": (
        *(f"pect_maj_t_{k}" for k in range(1, 7)),
        "pect_maj_c_1",
        "pect_maj_c_2",
    ),
}

#: ISB coordinates = DAS_TO_ISB @ DAS3 coordinates (DAS3: X lateral, Y up, Z posterior).
DAS_TO_ISB = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])


def _vec(text: str) -> np.ndarray:
    return np.array([float(v) for v in text.split()])


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def _xyz(o: np.ndarray) -> np.ndarray:
    e = np.eye(3)
    return _rot(e[0], o[0]) @ _rot(e[1], o[1]) @ _rot(e[2], o[2])


def _tf(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, p
    return M


def _joints(root: ET.Element) -> dict[str, tuple[str, np.ndarray]]:
    """child body → (parent body, 4×4 pose of the child body in the parent body) at the
    default coordinates, for every ``CustomJoint`` whose transform functions are constant or
    linear (the shoulder chain's are)."""
    coords = {
        c.get("name"): float(c.findtext("default_value", "0")) for c in root.iter("Coordinate")
    }
    out = {}
    for j in root.iter("CustomJoint"):
        frames = {
            f.get("name"): (
                f.findtext("socket_parent").split("/")[-1],
                _tf(_xyz(_vec(f.findtext("orientation"))), _vec(f.findtext("translation"))),
            )
            for f in j.find("frames").iter("PhysicalOffsetFrame")
        }
        parent = frames[j.findtext("socket_parent_frame")]
        child = frames[j.findtext("socket_child_frame")]
        R, p, ok = np.eye(3), np.zeros(3), True
        for ta in j.find("SpatialTransform").findall("TransformAxis"):
            axis, fn = _vec(ta.findtext("axis")), list(ta)[-1]
            name = (ta.findtext("coordinates") or "").strip()
            x = coords[name] if name else 0.0
            if fn.tag == "Constant":
                v = float(fn.findtext("value"))
            elif fn.tag == "LinearFunction":
                a, b = _vec(fn.findtext("coefficients"))
                v = a * x + b
            else:  # splines (wrist, hand): not on the shoulder chain
                ok = False
                break
            if ta.get("name").startswith("rotation"):
                R = R @ _rot(axis, v)
            else:
                p = p + v * axis
        if ok:
            out[child[0]] = (parent[0], parent[1] @ _tf(R, p) @ np.linalg.inv(child[1]))
    return out


def _pose(joints: dict, body: str) -> np.ndarray:
    M = np.eye(4)
    while body != "thorax":
        if body not in joints:
            raise ValueError(f"body {body!r} has no evaluable joint chain to the thorax")
        body, X = joints[body]
        M = X @ M
    return M


def read_elements(osim) -> dict[str, list[dict]]:
    """The DAS3 elements of the eleven muscles, in the frames of ``shoulder_muscles.json``.

    Parameters
    ----------
    osim : str or path-like
        DAS3's ``das4_v4.osim``.

    Returns
    -------
    dict
        muscle name (:data:`DAS3_MUSCLES`) → list of ``{"das": element name, "f_max": N,
        "origin": thorax frame centred on the GH centre (m), "insertion": humerus frame (m),
        "wrap": DAS3's wrap objects, "via_points": path points between origin and humerus,
        "humerus_points": path points on the humerus}``.

    Raises
    ------
    ValueError
        ``osim`` is not a file, or an element of :data:`DAS3_MUSCLES` is missing in it.
    """
    path = Path(osim)
    if not path.is_file():
        raise ValueError(f"osim must be DAS3's das4_v4.osim file, got {str(osim)!r}")
    root = ET.parse(path).getroot()
    joints = _joints(root)
    gh = _pose(joints, "humerus_r")[:3, 3]
    muscles = {m.get("name"): m for m in root.iter() if m.find("GeometryPath") is not None}
    out: dict[str, list[dict]] = {}
    for name, elements in DAS3_MUSCLES.items():
        rows = []
        for el in elements:
            if el not in muscles:
                raise ValueError(f"element {el!r} of {name!r} is not in {path.name}")
            m = muscles[el]
            gp = m.find("GeometryPath")
            pts = list(gp.find("PathPointSet").find("objects"))
            frames = [p.findtext("socket_parent_frame").split("/")[-1] for p in pts]
            if "humerus_r" not in frames:
                raise ValueError(f"element {el!r} does not insert on humerus_r")
            k = frames.index("humerus_r")
            first, last = pts[0], pts[k]
            M = _pose(joints, frames[0])
            o = M[:3, :3] @ _vec(first.findtext("location")) + M[:3, 3] - gh
            wraps = gp.find("PathWrapSet")
            rows.append(
                {
                    "das": el,
                    "f_max": float(m.findtext("max_isometric_force")),
                    "origin": np.round(DAS_TO_ISB @ o, 6).tolist(),
                    "insertion": np.round(DAS_TO_ISB @ _vec(last.findtext("location")), 6).tolist(),
                    "wrap": []
                    if wraps is None
                    else [w.findtext("wrap_object") for w in wraps.iter("PathWrap")],
                    "via_points": k - 1,
                    "humerus_points": len(pts) - k,
                }
            )
        out[name] = rows
    return out
