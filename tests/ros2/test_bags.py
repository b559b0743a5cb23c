"""ROS 2 bags in and out (issue 31, case 6).

Bags are written here with ``rosbags`` (the independent library) from this file's
own ``vision_msgs`` definitions, not semwm's, then replayed with ``semwm replay
BAG --ros2-detections TOPIC``; the world must equal the world a ``WorldModel``
builds from the same detections given directly. semwm's ROS 2 output is read
back with the same library and this file's definitions.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from semwm.cli import main
from semwm.knowledge import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.world import WorldModel

SIM1 = shipped_knowledge_path("sim1.yaml")  # 2-D; Cup, Can, CokeCan, BeerCan, Table
T0 = 1_764_066_060.0  # a robot's clock: epoch seconds

# vision_msgs 4.x, as its .msg files define them (written out here, apart from semwm's)
VISION_MSGS = {
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose"
    ),
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\nObjectHypothesisWithPose[] results\nBoundingBox3D bbox\nstring id"
    ),
    "vision_msgs/msg/Detection3DArray": "std_msgs/Header header\nDetection3D[] detections",
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y",
    "vision_msgs/msg/Pose2D": "Point2D position\nfloat64 theta",
    "vision_msgs/msg/BoundingBox2D": "Pose2D center\nfloat64 size_x\nfloat64 size_y",
    "vision_msgs/msg/Detection2D": (
        "std_msgs/Header header\nObjectHypothesisWithPose[] results\nBoundingBox2D bbox\nstring id"
    ),
    "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nDetection2D[] detections",
}


def make_store() -> Any:
    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in VISION_MSGS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


STORE = make_store()
T = STORE.types


def stamp(t: float) -> Any:
    sec = math.floor(t)
    return T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((t - sec) * 1e9))


def header(t: float, frame: str) -> Any:
    return T["std_msgs/msg/Header"](stamp=stamp(t), frame_id=frame)


def pose(xyz: Sequence[float], yaw: float = 0.0) -> Any:
    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    p = T["geometry_msgs/msg/Point"](x=xyz[0], y=xyz[1], z=xyz[2])
    return T["geometry_msgs/msg/Pose"](position=p, orientation=q)


def result(class_id: str, score: float, xyz: Sequence[float], var: Sequence[float]) -> Any:
    covariance = np.zeros(36)
    covariance[0], covariance[7], covariance[14] = var
    return T["vision_msgs/msg/ObjectHypothesisWithPose"](
        hypothesis=T["vision_msgs/msg/ObjectHypothesis"](class_id=class_id, score=score),
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose(xyz), covariance=covariance),
    )


def detection3d(t: float, frame: str, results: list[Any], det_id: str = "") -> Any:
    bbox = T["vision_msgs/msg/BoundingBox3D"](
        center=pose((0.0, 0.0, 0.0)), size=T["geometry_msgs/msg/Vector3"](x=0.1, y=0.1, z=0.1)
    )
    return T["vision_msgs/msg/Detection3D"](
        header=header(t, frame), results=results, bbox=bbox, id=det_id
    )


def array3d(t: float, frame: str, detections: list[Any]) -> Any:
    return T["vision_msgs/msg/Detection3DArray"](header=header(t, frame), detections=detections)


def write_bag(path: Path, topics: dict[str, tuple[str, Iterable[tuple[float, Any]]]]) -> Path:
    """A rosbag2 folder (MCAP storage): topic -> (type, [(log time, message)])."""
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, (msgtype, messages) in topics.items():
            connection = writer.add_connection(topic, msgtype, typestore=STORE)
            for log_time, message in messages:
                writer.write(
                    connection, round(log_time * 1e9), STORE.serialize_cdr(message, msgtype)
                )
    return path


CUP, COKE = (1.0, 2.0, 0.0), (3.0, 1.0, 0.0)
VAR = (0.01, 0.01, 0.01)


def scan_times(n: int = 20) -> list[float]:
    return [T0 + 0.1 * k for k in range(n)]


def good_bag(path: Path) -> Path:
    """Two objects seen 20 times at 10 Hz by "camera": a Cup (also scored as a
    BeerCan, less) and a CokeCan, with a little noise."""
    rng = np.random.default_rng(1)
    messages = []
    for t in scan_times():
        cup = tuple(np.add(CUP, [*rng.normal(0, 0.02, 2), 0.0]))
        coke = tuple(np.add(COKE, [*rng.normal(0, 0.02, 2), 0.0]))
        messages.append(
            (
                t,
                array3d(
                    t,
                    "camera",
                    [
                        detection3d(
                            t,
                            "camera",
                            [result("Cup", 0.9, cup, VAR), result("BeerCan", 0.1, cup, VAR)],
                        ),
                        detection3d(t, "camera", [result("CokeCan", 0.8, coke, VAR)]),
                    ],
                ),
            )
        )
    return write_bag(path, {"/detections": ("vision_msgs/msg/Detection3DArray", messages)})


def replay(bag: Path, out: Path, *extra: str) -> tuple[int, dict[str, Any], list[dict[str, Any]]]:
    status = main(
        ["replay", str(bag), "--ros2-detections", "/detections", "--knowledge", str(SIM1),
         "--out", str(out), "--no-progress", *extra]
    )  # fmt: skip
    if status != 0:
        return status, {}, []
    metrics = json.loads((out / "metrics.json").read_text())
    worlds = [json.loads(line) for line in (out / "world.jsonl").read_text().splitlines()]
    return status, metrics, worlds


def direct_world(bag: Path) -> dict[str, Any]:
    """The world a WorldModel builds from the bag's detections given directly (read
    back here with rosbags and this file's definitions)."""
    model = WorldModel(load_knowledge(SIM1), reorder_window=0.5)
    with Reader(bag) as reader:
        for connection, _, raw in reader.messages():
            message = STORE.deserialize_cdr(raw, connection.msgtype)
            t = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
            batch = []
            for d in message.detections:
                best = max(d.results, key=lambda r: r.hypothesis.score)
                p = best.pose.pose.position
                c = np.asarray(best.pose.covariance).reshape(6, 6)[:2, :2]
                batch.append(
                    {"time": t, "class": best.hypothesis.class_id, "position": [p.x, p.y],
                     "covariance": c.tolist(), "source": message.header.frame_id}
                )  # fmt: skip
            model.ingest(batch)
    return dict(json.loads(json.dumps(model.world().to_dict())))  # as world.jsonl has it


def test_a_bag_of_detection3d_arrays_replays_to_the_expected_world(tmp_path: Path) -> None:
    bag = good_bag(tmp_path / "robot_bag")
    status, metrics, worlds = replay(bag, tmp_path / "out")
    assert status == 0
    world = worlds[-1]
    assert world == direct_world(bag)  # exactly the world of the same detections
    assert world["time"] == pytest.approx(scan_times()[-1], abs=1e-6)  # the header stamps
    objects = {o["class"]: o for o in world["objects"]}
    assert set(objects) == {"Cup", "CokeCan"}
    assert objects["Cup"]["position"] == pytest.approx(CUP[:2], abs=0.03)
    assert objects["CokeCan"]["position"] == pytest.approx(COKE[:2], abs=0.03)
    ros2 = metrics["ros2"]
    assert (ros2["messages"], ros2["detections"], ros2["used"]) == (20, 40, 40)
    assert ros2["other_scores"] == 20  # Cup 0.9 over BeerCan 0.1: the top class used
    assert ros2["unknown_classes"] == {} and ros2["zero_covariance"] == 0
    assert ros2["out_of_order"] == 0 and metrics["refused_batches"] == 0


def test_a_bag_file_alone_replays_too(tmp_path: Path) -> None:
    bag = good_bag(tmp_path / "robot_bag")
    (mcap_file,) = bag.glob("*.mcap")
    status, _, worlds = replay(mcap_file, tmp_path / "out")
    assert status == 0 and worlds[-1] == direct_world(bag)


def test_unknown_classes_missing_covariances_and_late_stamps_are_reported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    times = scan_times(10)
    messages = []
    for k, t in enumerate(times):
        stamped = t - 2.0 if k == 6 else t  # one array stamped 2 s early: beyond the window
        detections = [
            detection3d(stamped, "camera", [result("Cup", 0.9, CUP, (0.0, 0.0, 0.0))]),  # no cov
            detection3d(stamped, "camera", [result("chair", 0.7, COKE, VAR)]),  # unknown
        ]
        messages.append((t, array3d(stamped, "camera", detections)))
    bag = write_bag(
        tmp_path / "bad_bag", {"/detections": ("vision_msgs/msg/Detection3DArray", messages)}
    )
    status, metrics, worlds = replay(bag, tmp_path / "out")
    assert status == 0
    out = capsys.readouterr().out
    assert "Traceback" not in out
    ros2 = metrics["ros2"]
    assert ros2["unknown_classes"] == {"chair": 10}
    assert ros2["zero_covariance"] == 10
    assert ros2["out_of_order"] == 1 and ros2["most_late_s"] == pytest.approx(
        1.9, abs=1e-6
    )  # 2 s before its own slot, 1.9 s before the one ahead
    assert metrics["refused_batches"] == 1  # the late one, beyond the 0.5 s reorder window
    assert "10 detections of classes the knowledge has not, left out: 'chair' x10" in out
    assert "--class-map FILE" in out
    assert "10 detections with an all-zero covariance" in out
    assert "1 messages stamped before an earlier one (up to 1.900 s)" in out
    (cup,) = worlds[-1]["objects"]
    assert cup["class"] == "Cup"  # the Cup, with the class's measurement noise


def test_a_class_map_renames_and_drops_classes(tmp_path: Path) -> None:
    messages = [
        (t, array3d(t, "camera", [
            detection3d(t, "camera", [result("47", 0.9, CUP, VAR)]),
            detection3d(t, "camera", [result("tv", 0.9, COKE, VAR)]),
        ]))
        for t in scan_times(10)
    ]  # fmt: skip
    bag = write_bag(
        tmp_path / "bag", {"/detections": ("vision_msgs/msg/Detection3DArray", messages)}
    )
    mapping = tmp_path / "classes.yaml"
    mapping.write_text('# COCO ids\n"47": Cup\ntv: null\n')
    status, metrics, worlds = replay(bag, tmp_path / "out", "--class-map", str(mapping))
    assert status == 0
    assert [o["class"] for o in worlds[-1]["objects"]] == ["Cup"]
    assert metrics["ros2"]["dropped_classes"] == {"tv": 10}
    assert metrics["ros2"]["unknown_classes"] == {}


def test_a_class_map_naming_an_unknown_class_is_refused_with_its_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = good_bag(tmp_path / "bag")
    mapping = tmp_path / "classes.yaml"
    mapping.write_text('"47": Cup\n"62": Chair\n')
    status, _, _ = replay(bag, tmp_path / "out", "--class-map", str(mapping))
    assert status == 2
    err = capsys.readouterr().err
    assert f"{mapping}:2: '62' maps to 'Chair', which the knowledge has not" in err
    assert not (tmp_path / "out").exists()


def test_a_sensor_pose_topic_moves_detections_into_the_world_frame(tmp_path: Path) -> None:
    # the robot stands at (2, 1) facing +y (yaw 90 degrees); it sees a Cup 1 m ahead
    sensor_at = (2.0, 1.0, 0.0)
    times = scan_times(10)
    poses = [
        (t, T["geometry_msgs/msg/PoseStamped"](header=header(t - 0.05, "map"), pose=pose(sensor_at, math.pi / 2)))
        for t in times
    ]  # fmt: skip
    ahead = (1.0, 0.0, 0.0)
    messages = [
        (t, array3d(t, "base_camera", [detection3d(t, "base_camera", [result("Cup", 0.9, ahead, (0.04, 0.01, 0.01))])]))
        for t in times
    ]  # fmt: skip
    bag = write_bag(
        tmp_path / "bag",
        {
            "/robot/pose": ("geometry_msgs/msg/PoseStamped", poses),
            "/detections": ("vision_msgs/msg/Detection3DArray", messages),
        },
    )
    status, metrics, worlds = replay(bag, tmp_path / "out", "--ros2-pose", "/robot/pose")
    assert status == 0
    (cup,) = worlds[-1]["objects"]
    assert cup["position"] == pytest.approx([2.0, 2.0], abs=1e-6)
    # the sensor's long axis (x, 0.04) is the world's y after the turn
    assert cup["covariance"][1][1] > cup["covariance"][0][0]
    assert metrics["ros2"]["used"] == 10 and metrics["ros2"]["no_pose"] == 0


def test_detection2d_arrays_with_a_pose_in_results(tmp_path: Path) -> None:
    messages = []
    for t in scan_times(10):
        bbox = T["vision_msgs/msg/BoundingBox2D"](
            center=T["vision_msgs/msg/Pose2D"](
                position=T["vision_msgs/msg/Point2D"](x=320.0, y=240.0), theta=0.0
            ),
            size_x=40.0,
            size_y=30.0,
        )
        located = T["vision_msgs/msg/Detection2D"](
            header=header(t, "camera"), results=[result("Cup", 0.9, CUP, VAR)], bbox=bbox, id=""
        )
        pixels_only = T["vision_msgs/msg/Detection2D"](
            header=header(t, "camera"),
            results=[result("CokeCan", 0.9, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))],
            bbox=bbox,
            id="",
        )
        messages.append(
            (t, T["vision_msgs/msg/Detection2DArray"](header=header(t, "camera"), detections=[located, pixels_only]))
        )  # fmt: skip
    bag = write_bag(
        tmp_path / "bag", {"/detections": ("vision_msgs/msg/Detection2DArray", messages)}
    )
    status, metrics, worlds = replay(bag, tmp_path / "out")
    assert status == 0
    (cup,) = worlds[-1]["objects"]
    assert cup["class"] == "Cup" and cup["position"] == pytest.approx(CUP[:2], abs=1e-6)
    assert metrics["ros2"]["no_position"] == 10


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--ros2-detections", "/nothere"], "no topic /nothere; the bag has /detections (vision_msgs/msg/Detection3DArray)"),
        (["--ros2-detections", "/detections", "--ros2-pose", "/detections"], "/detections is vision_msgs/msg/Detection3DArray; expected one of geometry_msgs/msg/PoseStamped"),
    ],
)  # fmt: skip
def test_a_wrong_topic_is_one_line_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    bag = good_bag(tmp_path / "bag")
    status = main(["replay", str(bag), "--knowledge", str(SIM1), "--out", str(tmp_path / "out"),
                   "--no-progress", *argv])  # fmt: skip
    assert status == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_bag_without_knowledge_says_to_give_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = good_bag(tmp_path / "bag")
    status = main(["replay", str(bag), "--ros2-detections", "/detections", "--no-progress"])
    assert status == 2
    assert "a ROS 2 bag carries no knowledge: pass --knowledge FILE" in capsys.readouterr().err


def test_the_world_written_as_ros2_detection3d_arrays_reads_back(tmp_path: Path) -> None:
    out_bag = tmp_path / "world_bag"
    status = main(["replay", "sim1", "--out", str(tmp_path / "out"), "--ros2-out", str(out_bag),
                   "--no-progress"])  # fmt: skip
    assert status == 0
    worlds = [
        json.loads(line) for line in (tmp_path / "out" / "world.jsonl").read_text().splitlines()
    ]
    with Reader(out_bag) as reader:
        (connection,) = reader.connections
        assert (connection.topic, connection.msgtype) == (
            "/semwm/world",
            "vision_msgs/msg/Detection3DArray",
        )
        messages = [
            (log_time, STORE.deserialize_cdr(raw, connection.msgtype))
            for _, log_time, raw in reader.messages()
        ]
    assert len(messages) == len(worlds)
    for (log_time, message), world in zip(messages, worlds, strict=True):
        t = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
        assert t == pytest.approx(world["time"], abs=1e-9)
        assert log_time == round(world["time"] * 1e9)
        assert message.header.frame_id == "world"
        assert [d.id for d in message.detections] == [str(o["id"]) for o in world["objects"]]
        for d, o in zip(message.detections, world["objects"], strict=True):
            scores = {r.hypothesis.class_id: r.hypothesis.score for r in d.results}
            probabilities = o["class_probabilities"] or {o["class"]: 1.0}
            assert scores == pytest.approx(
                {c: o["existence"] * p for c, p in probabilities.items()}
            )
            assert sum(scores.values()) == pytest.approx(
                o["existence"] * sum(probabilities.values())
            )
            best = d.results[0]
            assert best.hypothesis.class_id == max(probabilities, key=probabilities.__getitem__)
            position = best.pose.pose.position
            assert [position.x, position.y] == pytest.approx(o["position"])
            covariance = np.asarray(best.pose.covariance).reshape(6, 6)
            assert covariance[:2, :2] == pytest.approx(np.asarray(o["covariance"]))
    assert any(message.detections for _, message in messages)
    # as ROS 2 tools and Foxglove expect it: a rosbag2 folder whose MCAP file has a
    # ros2msg schema and CDR messages (read here with the mcap library)
    from mcap.reader import make_reader

    (mcap_file,) = out_bag.glob("*.mcap")
    assert (out_bag / "metadata.yaml").is_file()
    with mcap_file.open("rb") as handle:
        summary = make_reader(handle).get_summary()
    assert summary is not None
    (schema,) = summary.schemas.values()
    (channel,) = summary.channels.values()
    assert (schema.name, schema.encoding) == ("vision_msgs/msg/Detection3DArray", "ros2msg")
    assert (channel.topic, channel.message_encoding) == ("/semwm/world", "cdr")


def test_ros2_out_does_not_overwrite(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "world_bag").mkdir()
    status = main(["replay", "sim1", "--ros2-out", str(tmp_path / "world_bag"), "--out",
                   str(tmp_path / "out"), "--no-progress"])  # fmt: skip
    assert status == 2
    assert "exists already; not overwriting it" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_semwm_record_of_a_bag_replays_to_the_same_world(tmp_path: Path) -> None:
    bag = good_bag(tmp_path / "robot_bag")
    recording = tmp_path / "robot.mcap"
    status = main(["record", str(bag), str(recording), "--ros2-detections", "/detections",
                   "--knowledge", str(SIM1), "--ros2-out", str(tmp_path / "world_bag"),
                   "--no-progress"])  # fmt: skip
    assert status == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["robot.mcap", "robot_bag", "world_bag"]
    assert main(["replay", str(recording), "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    lines = (tmp_path / "out" / "world.jsonl").read_text().splitlines()
    assert json.loads(lines[-1]) == direct_world(bag)


def test_arrays_without_a_stamp_take_the_log_time(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    messages = [
        (t, array3d(0.0, "camera", [detection3d(0.0, "camera", [result("Cup", 0.9, CUP, VAR)])]))
        for t in scan_times(10)
    ]
    bag = write_bag(
        tmp_path / "bag", {"/detections": ("vision_msgs/msg/Detection3DArray", messages)}
    )
    status, metrics, worlds = replay(bag, tmp_path / "out")
    assert status == 0
    assert metrics["ros2"]["no_stamp"] == 10
    assert worlds[-1]["time"] == pytest.approx(scan_times(10)[-1], abs=1e-6)
    assert (
        "10 messages without a header stamp (0): the bag's log time used" in capsys.readouterr().out
    )


@pytest.mark.parametrize("as_file", [False, True], ids=["folder", "mcap file"])
def test_a_bag_given_without_ros2_detections_says_what_it_holds(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], as_file: bool
) -> None:
    bag = good_bag(tmp_path / "bag")
    source = next(bag.glob("*.mcap")) if as_file else bag
    status = main(["replay", str(source), "--out", str(tmp_path / "out"), "--no-progress"])
    assert status == 2
    err = capsys.readouterr().err
    assert f"{source} is a ROS 2 bag (/detections (vision_msgs/msg/Detection3DArray))" in err
    assert "pass --ros2-detections TOPIC and --knowledge FILE" in err
    assert not (tmp_path / "out").exists()
