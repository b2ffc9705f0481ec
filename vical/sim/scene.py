"""The MuJoCo calibration scene: Panda + sensor rig + calibration board, and the frames code reads from it.

The board is a checkerboard or a Kalibr aprilgrid (``sim.board.kind``). ``build_model``
compiles ``assets/scene.xml`` with the board placed and textured from the sim config. Frame
conventions are those of ``docs/conventions.md``; this module holds the one MuJoCo-to-OpenCV
camera conversion of vical (``camera_pose_cv``).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import mujoco
import numpy as np

from vical.data import Target
from vical.geometry import euler_to_matrix, make_transform, matrix_to_quat, quat_to_matrix
from vical.sim.settings import BoardConfig, SimConfig

ASSET_DIR = Path(__file__).resolve().parent / "assets"
SCENE_XML = ASSET_DIR / "scene.xml"
BOARD_TEXTURE = "board.png"

# OpenCV optical frame from MuJoCo's camera frame (looks along -z, y up): R_cv = R_mj @ diag(1, -1, -1).
_MJ_TO_CV = np.diag([1.0, -1.0, -1.0])
# Board axes in the camera body frame when the board faces the camera upright: grid rows (board x)
# go down the image (-body z), columns (board y) go right (-body y), board z points back (-body x).
_R_BODY_BOARD_FACING = np.array([[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0]])
# An aprilgrid upright as printed: board x goes right (-body y), y up (+body z), z points back (-body x).
_R_BODY_APRILGRID_FACING = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
APRILGRID_BITS_PER_TAG = 10  # tag36h11: 6 data bits + 2 black border bits on each side
STAND_CLEARANCE = 0.03  # [m] the stand's post stands this far behind the board's printed side
STAND_POST_HALF_WIDTH = 0.02  # [m]
PANDA_ROOT = "link0"  # the Panda's root body in assets/panda.xml
VISUAL_GROUP = 2  # assets/panda.xml's class "visual" (no collision; "collision" is group 3)


class SceneError(RuntimeError):
    """The scene files are missing or inconsistent with what vical expects."""


def board_texture_png(target: Target, border_squares: float, px_per_square: int) -> bytes:
    """PNG bytes of the printed board for MuJoCo's asset dict.

    MuJoCo maps the first texture row to the plane's +y edge and texture columns along +x.
    Checkerboard (``Target.pattern_image``): the pattern's rows follow board x and its columns
    board y, so the image is transposed and then flipped top-to-bottom, after which texture
    column = board x and row 0 = largest board y. Aprilgrid (``Target.aprilgrid_image``, with
    ``px_per_square / 10`` px per tag bit): already drawn with columns along board x and row 0 at
    the largest board y, so it is used as it is.
    """
    if target.kind == "aprilgrid":
        img = target.aprilgrid_image(px_per_bit=px_per_square // APRILGRID_BITS_PER_TAG)
    else:
        img = target.pattern_image(px_per_square=px_per_square, border_squares=border_squares)
        img = np.ascontiguousarray(img.T[::-1])
    ok, png = cv2.imencode(".png", img)
    if not ok:
        raise SceneError("could not encode the board texture as PNG")
    return png.tobytes()


def board_half_size(target: Target, border_squares: float) -> np.ndarray:
    """(2,) [m] half extent of the printed board along board x and y, centred on ``target.center``.

    Checkerboard: the squares and ``border_squares`` of white. Aprilgrid: the tags, their gaps and
    Kalibr's margin of two gaps on every side (``Target.aprilgrid_image``).
    """
    if target.kind == "aprilgrid":
        size, gap = target.row_spacing, target.tag_spacing * target.row_spacing
        tags = np.array([target.cols, target.rows])  # board x runs along the tag columns
        return 0.5 * (tags * size + (tags + 3) * gap)
    squares = np.array([target.rows + 1, target.cols + 1]) + 2.0 * border_squares
    return 0.5 * squares * np.array([target.row_spacing, target.col_spacing])


def board_pose_from_camera(T_world_body: np.ndarray, board: BoardConfig) -> np.ndarray:
    """Board pose ``T_world_board`` (4, 4) for the camera body pose ``T_world_body`` at home.

    The board centre sits ``board.distance`` along the optical axis (body x), shifted by
    ``board.offset`` along body y and z; the board faces the camera upright and is then rotated
    by ``board.tilt_rpy`` about its centre.
    """
    target = board.target
    centre_body = np.array([board.distance, board.offset[0], board.offset[1]])
    facing = _R_BODY_APRILGRID_FACING if target.kind == "aprilgrid" else _R_BODY_BOARD_FACING
    R_world_board = T_world_body[:3, :3] @ facing @ euler_to_matrix(board.tilt_rpy)
    centre_world = T_world_body[:3, :3] @ centre_body + T_world_body[:3, 3]
    return make_transform(R_world_board, centre_world - R_world_board @ target.center)


def _home_camera_body_pose(spec: mujoco.MjSpec) -> np.ndarray:
    """``T_world_body`` (4, 4) of ``cam_body`` at the ``home`` keyframe of the compiled spec."""
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_kinematics(model, data)
    body = model.body("cam_body").id
    return make_transform(data.xmat[body].reshape(3, 3), data.xpos[body])


def start_camera_body_pose(spec: mujoco.MjSpec, cfg: SimConfig) -> np.ndarray:
    """``T_world_body`` (4, 4) of ``cam_body`` at the episode start: ``cfg.start``, else the ``home`` keyframe."""
    if cfg.start is None:
        return _home_camera_body_pose(spec)
    return make_transform(euler_to_matrix(cfg.start.rpy), cfg.start.position)


def _place_stand(spec: mujoco.MjSpec, T_world_board: np.ndarray, target: Target) -> None:
    """Stand the post on the floor behind the board centre, up to the centre's height, with its foot plate."""
    normal = T_world_board[:3, 2]  # out of the printed side
    centre = T_world_board[:3, :3] @ target.center + T_world_board[:3, 3]
    foot = centre - STAND_CLEARANCE * normal
    height = max(float(centre[2]), 2 * STAND_POST_HALF_WIDTH)
    body = spec.body("board_stand")
    body.pos = [foot[0], foot[1], 0.0]
    post = spec.geom("stand_post")
    post.size = [STAND_POST_HALF_WIDTH, STAND_POST_HALF_WIDTH, 0.5 * height]
    post.pos = [0.0, 0.0, 0.5 * height]


def build_model(cfg: SimConfig) -> tuple[mujoco.MjModel, np.ndarray]:
    """Compile the scene for ``cfg``: physics step, board texture, size and pose, and its stand.

    Returns:
        model: the compiled ``MjModel``.
        T_world_board: (4, 4) board pose (Kalibr board frame in world).
    """
    spec, T_world_board, _ = _scene_spec(cfg)
    return spec.compile(), T_world_board


def build_hand_held_model(cfg: SimConfig) -> tuple[mujoco.MjModel, np.ndarray, np.ndarray]:
    """The scene of ``build_model`` with the sensor held by a person instead of the Panda: ``cam_body`` a mocap
    body (posed by ``data.mocap_pos/mocap_quat``) carrying the camera, sites and housing the flange carries.

    Returns:
        model: the compiled ``MjModel`` (no Panda, no joints).
        T_world_board: (4, 4) board pose, where ``build_model`` puts it.
        T_world_start: (4, 4) ``cam_body``'s start pose (the Panda's, ``start_camera_body_pose``).
    """
    spec, T_world_board, T_world_start = _scene_spec(cfg)
    rig = _rig_in_body(spec.compile())
    for kind in ("excludes", "keys", "actuators", "sensors", "tendons", "equalities"):
        for element in list(getattr(spec, kind)):
            spec.delete(element)
    spec.delete(spec.body(PANDA_ROOT))
    hand = spec.worldbody.add_body(name="cam_body", mocap=True, pos=T_world_start[:3, 3],
                                   quat=matrix_to_quat(T_world_start[:3, :3]))  # fmt: skip
    camera = rig["camera"]
    hand.add_camera(name="cam", pos=camera["pos"], quat=camera["quat"], fovy=camera["fovy"])
    for name, site in rig["sites"].items():
        hand.add_site(name=name, pos=site["pos"], quat=site["quat"], size=site["size"], rgba=site["rgba"])
    for geom in rig["geoms"]:
        hand.add_geom(**geom, contype=0, conaffinity=0)  # held in the air: nothing collides
    return spec.compile(), T_world_board, T_world_start


def _rig_in_body(model: mujoco.MjModel) -> dict:
    """What ``cam_body`` carries in the compiled Panda scene, in its frame: the camera, the sites, the visual
    housing (the one description of the rig, assets/panda.xml's)."""
    body = model.body("cam_body").id
    camera = model.camera("cam").id
    sites = {name: model.site(name).id for name in ("ee", "imu")}
    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == body and model.geom_group[g] == VISUAL_GROUP]
    return {
        "camera": {
            "pos": model.cam_pos[camera].copy(),
            "quat": model.cam_quat[camera].copy(),
            "fovy": float(model.cam_fovy[camera]),
        },
        "sites": {
            name: {
                "pos": model.site_pos[i].copy(),
                "quat": model.site_quat[i].copy(),
                "size": model.site_size[i].copy(),
                "rgba": model.site_rgba[i].copy(),
            }
            for name, i in sites.items()
        },
        "geoms": [
            {
                "type": mujoco.mjtGeom(int(model.geom_type[g])),
                "size": model.geom_size[g].copy(),
                "pos": model.geom_pos[g].copy(),
                "quat": model.geom_quat[g].copy(),
                "rgba": model.geom_rgba[g].copy(),
            }
            for g in geoms
        ],
    }


def _scene_spec(cfg: SimConfig) -> tuple[mujoco.MjSpec, np.ndarray, np.ndarray]:
    """The scene's spec for ``cfg`` (board placed, textured and standing), the board pose and the camera body's
    start pose."""
    if not SCENE_XML.is_file():
        raise SceneError(f"scene file {SCENE_XML} is missing; reinstall vical")
    board = cfg.board
    target = board.target
    assets = {BOARD_TEXTURE: board_texture_png(target, board.border_squares, board.px_per_square)}
    spec = mujoco.MjSpec.from_file(str(SCENE_XML), assets=assets)
    spec.option.timestep = cfg.physics.timestep
    T_world_start = start_camera_body_pose(spec, cfg)
    T_world_board = board_pose_from_camera(T_world_start, board)
    body = spec.body("board")
    body.pos = T_world_board[:3, 3]
    body.quat = matrix_to_quat(T_world_board[:3, :3])
    half = board_half_size(target, board.border_squares)
    for name, thickness in (("board_print", 0.01), ("board_backing", 0.005)):
        geom = spec.geom(name)
        geom.pos = [target.center[0], target.center[1], geom.pos[2]]
        geom.size = [half[0], half[1], thickness]
    _place_stand(spec, T_world_board, target)
    return spec, T_world_board, T_world_start


def site_pose(model: mujoco.MjModel, data: mujoco.MjData, name: str) -> np.ndarray:
    """``T_world_site`` (4, 4) of site ``name`` from the data's current kinematics."""
    i = model.site(name).id
    return make_transform(data.site_xmat[i].reshape(3, 3), data.site_xpos[i])


def body_pose(model: mujoco.MjModel, data: mujoco.MjData, name: str) -> np.ndarray:
    """``T_world_body`` (4, 4) of body ``name`` from the data's current kinematics."""
    i = model.body(name).id
    return make_transform(data.xmat[i].reshape(3, 3), data.xpos[i])


def camera_pose_cv(model: mujoco.MjModel, data: mujoco.MjData, camera: str = "cam") -> np.ndarray:
    """``T_world_cam`` (4, 4) of MuJoCo camera ``camera`` in the OpenCV/Kalibr optical convention.

    MuJoCo cameras look along their -z with +y up; the optical frame looks along +z with +y down
    in the image: ``R_world_cam = R_world_cammj @ diag(1, -1, -1)``. This is vical's only place
    for that flip. Uses ``data.cam_xpos/cam_xmat`` (valid after ``mj_kinematics``/``mj_forward``).
    """
    i = model.camera(camera).id
    R_world_cam = data.cam_xmat[i].reshape(3, 3) @ _MJ_TO_CV
    return make_transform(R_world_cam, data.cam_xpos[i])


def set_imu_pose(model: mujoco.MjModel, T_body_imu: np.ndarray) -> None:
    """Place site ``imu`` at ``T_body_imu`` (4, 4) in the ``cam_body`` frame (per episode).

    Writes ``model.site_pos``/``site_quat`` (MuJoCo quaternions are [w, x, y, z]) and clears the
    site's same-frame shortcut; the data's
    site poses and IMU readings follow at the next ``mj_kinematics``/``mj_forward``/``mj_step``.
    """
    T = np.asarray(T_body_imu, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"T_body_imu must be a finite (4, 4) transform, got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError("T_body_imu's rotation block is not a rotation matrix (R^T R = I, det R = 1)")
    i = model.site("imu").id
    if model.site_bodyid[i] != model.body("cam_body").id:
        raise SceneError("site 'imu' must be a child of body 'cam_body'")
    model.site_pos[i] = T[:3, 3]
    model.site_quat[i] = matrix_to_quat(R)
    # The compiler marks a site at its body's origin as "same frame" and then skips site_pos/quat.
    model.site_sameframe[i] = mujoco.mjtSameFrame.mjSAMEFRAME_NONE


def imu_pose_in_body(model: mujoco.MjModel) -> np.ndarray:
    """``T_body_imu`` (4, 4) currently set in the model (inverse of ``set_imu_pose``)."""
    i = model.site("imu").id
    return make_transform(quat_to_matrix(model.site_quat[i]), model.site_pos[i])
