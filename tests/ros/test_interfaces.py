"""Interface definitions: parsing, generated classes and CDR bytes against rosbags."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.typesys import get_types_from_msg

from biped_opt.interface_defs import InterfaceError, find_msg_defs, srv_to_idl
from biped_opt.ros.interfaces import load_interfaces

PKG = "biped_opt_interfaces"


@pytest.fixture(scope="module")
def ifc():
    return load_interfaces()


def test_every_definition_parses(ifc):
    root = find_msg_defs()
    msgs = sorted(p.stem for p in (root / "msg").glob("*.msg"))
    srvs = sorted(p.stem for p in (root / "srv").glob("*.srv"))
    assert msgs == ["BipedState", "ContactMode", "StudyRow", "SweepPoint", "SystemInfo",
                    "SystemState"]
    assert srvs == ["OptimalPolicy", "Simulate", "StudyPoint"]
    actions = sorted(p.stem for p in (root / "action").glob("*.action"))
    assert actions == ["Study"]
    for name in msgs:
        assert f"{PKG}/msg/{name}" in ifc.typestore.fielddefs
    for name in srvs:
        for half in ("Request", "Response"):
            assert f"{PKG}/srv/{name}_{half}" in ifc.typestore.fielddefs
    for name in actions:
        for part in ("Goal", "Result", "Feedback", "SendGoal_Request", "SendGoal_Response",
                     "GetResult_Request", "GetResult_Response", "FeedbackMessage"):
            assert f"{PKG}/action/{name}_{part}" in ifc.typestore.fielddefs


def test_action_types_follow_rosidl(ifc):
    """The structs rosidl derives from Study.action, with rmw_cyclonedds' DDS type names."""
    study = ifc.actions[f"{PKG}/action/Study"]
    impl = study.Impl
    assert impl.SendGoalService.RequestWire.__idl_typename__ == \
        f"{PKG}::action::dds_::Study_SendGoal_Request_"
    assert impl.GetResultService.ResponseWire.__idl_typename__ == \
        f"{PKG}::action::dds_::Study_GetResult_Response_"
    assert impl.CancelGoalService.RequestWire.__idl_typename__ == \
        "action_msgs::srv::dds_::CancelGoal_Request_"
    assert impl.FeedbackMessage.__idl_typename__ == f"{PKG}::action::dds_::Study_FeedbackMessage_"
    assert impl.GoalStatusMessage.__idl_typename__ == "action_msgs::msg::dds_::GoalStatusArray_"
    send = impl.SendGoalService.Request()
    assert list(send.__dataclass_fields__) == ["goal_id", "goal"]
    assert list(send.goal_id.uuid) == [0] * 16 and list(send.goal.__dataclass_fields__) == [
        "study", "out"]
    assert list(impl.GetResultService.Response.__dataclass_fields__) == ["status", "result"]
    assert list(impl.CancelGoalService.Response.__dataclass_fields__) == [
        "return_code", "goals_canceling"]
    assert impl.CancelGoalService.Response.ERROR_GOAL_TERMINATED == 3


def test_srv_idl_matches_msg_parser(ifc):
    """Each .srv half converted to IDL gives the fields rosbags' .msg parser gives."""
    root = find_msg_defs()
    for path in (root / "srv").glob("*.srv"):
        request, response = path.read_text().split("---")
        for text, half in ((request, "Request"), (response, "Response")):
            # rosbags' .msg parser files everything under msg/; only the fields matter here.
            name = f"{PKG}/msg/{path.stem}_{half}"
            direct = get_types_from_msg(text, name)[name]
            assert ifc.typestore.fielddefs[f"{PKG}/srv/{path.stem}_{half}"] == direct


def test_srv_to_idl_errors():
    with pytest.raises(InterfaceError, match="separator"):
        srv_to_idl("int32 a\n", PKG, "X")
    with pytest.raises(InterfaceError, match="default value"):
        srv_to_idl("int32 a 5\n---\n", PKG, "X")
    idl = srv_to_idl("uint8 A=1\nstring<=8 s\nint32[<=3] b\n---\n", PKG, "X")
    assert "const uint8 A = 1;" in idl and "string<8> s;" in idl
    assert "sequence<int32, 3> b;" in idl and "structure_needs_at_least_one_member" in idl


def test_message_classes(ifc):
    mode = ifc.message_class(f"{PKG}/msg/ContactMode")
    assert (mode.AIR, mode.LEFT, mode.RIGHT, mode.GROUND) == (0, 1, 2, 3)
    state_cls = ifc.message_class(f"{PKG}/msg/BipedState")
    state = state_cls(maneuver="touchdown", q=[1.0] * 7)
    assert state.qdot == [0.0] * 7 and state.contact_force == [0.0, 0.0]
    assert state.header.stamp.sec == 0
    assert state_cls.__name__ == "BipedState"
    with pytest.raises(AttributeError, match="no field 'states'"):
        state_cls().states = []  # a typo must not be dropped silently on the wire
    # Fields are independent between instances (no shared mutable defaults).
    other = state_cls()
    other.header.stamp.sec = 3
    assert state_cls().header.stamp.sec == 0


def _rosbags(ifc, name, **values):
    return ifc.typestore.types[name](**values)


def test_cdr_bytes_match_rosbags(ifc):
    ts = ifc.typestore
    time = _rosbags(ifc, "builtin_interfaces/msg/Time", sec=12, nanosec=345)
    header = _rosbags(ifc, "std_msgs/msg/Header", stamp=time, frame_id="world")
    q = np.linspace(-1.0, 1.0, 7)
    ref = _rosbags(
        ifc, f"{PKG}/msg/BipedState", header=header, maneuver="liftoff", theta0=0.1, t=0.25,
        q=q, qdot=q[::-1].copy(), contact_mode=3, contact_force=np.array([1.5, -2.0]),
    )
    state_cls = ifc.message_class(f"{PKG}/msg/BipedState")
    ours = state_cls(maneuver="liftoff", theta0=0.1, t=0.25, q=list(q), qdot=list(q[::-1]),
                     contact_mode=3, contact_force=[1.5, -2.0])
    ours.header.stamp.sec, ours.header.stamp.nanosec, ours.header.frame_id = 12, 345, "world"
    wire = bytes(ours.serialize(use_version_2=False))
    assert wire[:4] == b"\x00\x01\x00\x00"  # XCDR1 little endian
    assert wire == bytes(ts.serialize_cdr(ref, f"{PKG}/msg/BipedState"))

    ref = _rosbags(
        ifc, f"{PKG}/msg/SweepPoint", header=header, maneuver="touchdown", theta0=-0.2,
        optimal=True, policy=np.array([0.5, 0.25]), value=3.0, outcome=1.0, t_final=0.7,
        mode_sequence=np.array([0, 1, 3], dtype=np.uint8), event_times=np.array([0.1, 0.2]),
    )
    sweep_cls = ifc.message_class(f"{PKG}/msg/SweepPoint")
    ours = sweep_cls(maneuver="touchdown", theta0=-0.2, optimal=True, policy=[0.5, 0.25],
                     value=3.0, outcome=1.0, t_final=0.7, mode_sequence=[0, 1, 3],
                     event_times=[0.1, 0.2])
    ours.header.stamp.sec, ours.header.stamp.nanosec, ours.header.frame_id = 12, 345, "world"
    assert bytes(ours.serialize(use_version_2=False)) == bytes(
        ts.serialize_cdr(ref, f"{PKG}/msg/SweepPoint"))


def test_system_messages_cdr_bytes_match_rosbags(ifc):
    """SystemState (sequences, uint32 mask) and SystemInfo (string sequences) as rosbags."""
    ts = ifc.typestore
    name = f"{PKG}/msg/SystemState"
    header = _rosbags(ifc, "std_msgs/msg/Header",
                      stamp=_rosbags(ifc, "builtin_interfaces/msg/Time", sec=1, nanosec=2),
                      frame_id="walker3")
    ref = _rosbags(ifc, name, header=header, system="walker3", maneuver="touchdown", s=0.1,
                   t=0.5, q=np.arange(9.0), qdot=-np.arange(9.0), contact_mode=(1 << 31) | 5,
                   contact_force=np.array([0.5, 0.0, 2.0]))
    ours = ifc.message_class(name)(system="walker3", maneuver="touchdown", s=0.1, t=0.5,
                                   q=list(np.arange(9.0)), qdot=list(-np.arange(9.0)),
                                   contact_mode=(1 << 31) | 5, contact_force=[0.5, 0.0, 2.0])
    ours.header.stamp.sec, ours.header.stamp.nanosec, ours.header.frame_id = 1, 2, "walker3"
    assert bytes(ours.serialize(use_version_2=False)) == bytes(ts.serialize_cdr(ref, name))
    name = f"{PKG}/msg/SystemInfo"
    fields = {"system": "bar", "source": "bar.py", "coordinates": ["x", "z", "th"],
              "constraints": ["left", "right"], "inputs": [], "parameter_names": ["m"],
              "maneuvers": ["drop"]}
    numbers = {"parameter_values": [1.0], "s_min": [-0.3], "s_max": [0.3]}
    ref = _rosbags(ifc, name, **fields, **{k: np.array(v) for k, v in numbers.items()})
    ours = ifc.message_class(name)(**fields, **numbers)
    assert bytes(ours.serialize(use_version_2=False)) == bytes(ts.serialize_cdr(ref, name))


def test_service_wire_has_request_header(ifc):
    ts = ifc.typestore
    svc = ifc.services[f"{PKG}/srv/Simulate"]
    request = svc.Request(maneuver="touchdown", theta0=0.05, inputs=[1.0, 2.0, 3.0],
                          real_time_factor=0.0)
    wire = svc.RequestWire(body=request)
    wire.header.guid, wire.header.seq = 0x0123456789ABCDEF, 42
    data = bytes(wire.serialize(use_version_2=False))
    ref = _rosbags(ifc, f"{PKG}/srv/Simulate_Request", maneuver="touchdown", theta0=0.05,
                   inputs=np.array([1.0, 2.0, 3.0]), real_time_factor=0.0)
    plain = bytes(ts.serialize_cdr(ref, f"{PKG}/srv/Simulate_Request"))
    header = (0x0123456789ABCDEF).to_bytes(8, "little") + (42).to_bytes(8, "little")
    assert data == plain[:4] + header + plain[4:]
    back = svc.RequestWire.deserialize(data)
    assert back.header.guid == 0x0123456789ABCDEF and back.body == request

    svc = ifc.services[f"{PKG}/srv/OptimalPolicy"]
    response = svc.Response(success=True, message="ok", policy=[1.0, 2.0], value=0.5,
                            mode_sequence=[1, 3], value_derivative=[0.1, 0.2],
                            inputs=[1.0, 2.0, 0.0], contact_modes=[1, 3, 70000],
                            decision_names=["u1", "u_body"], system_inputs=[1.0, 2.0, 0.0, 4.0])
    data = bytes(svc.ResponseWire(body=response).serialize(use_version_2=False))
    ref = _rosbags(
        ifc, f"{PKG}/srv/OptimalPolicy_Response", success=True, message="ok",
        policy=np.array([1.0, 2.0]), value=0.5, outcome=0.0, t_final=0.0,
        mode_sequence=np.array([1, 3], dtype=np.uint8), event_times=np.zeros(0),
        value_derivative=np.array([0.1, 0.2]), inputs=np.array([1.0, 2.0, 0.0]),
        contact_modes=np.array([1, 3, 70000], dtype=np.uint32),
        decision_names=["u1", "u_body"], system_inputs=np.array([1.0, 2.0, 0.0, 4.0]),
    )
    plain = bytes(ts.serialize_cdr(ref, f"{PKG}/srv/OptimalPolicy_Response"))
    assert data == plain[:4] + bytes(16) + plain[4:]


def test_interface_package_files():
    """package.xml and CMakeLists.txt declare a buildable rosidl interface package."""
    import xml.etree.ElementTree as ET

    root = find_msg_defs()
    if not (root / "package.xml").is_file():
        pytest.skip("definitions come from an installed package without its build files")
    pkg = ET.parse(root / "package.xml").getroot()
    assert pkg.get("format") == "3" and pkg.findtext("name") == PKG
    assert pkg.findtext("member_of_group") == "rosidl_interface_packages"
    assert {"std_msgs", "action_msgs"} <= {e.text for e in pkg.findall("depend")}
    assert pkg.find("export").findtext("build_type") == "ament_cmake"
    cmake = (root / "CMakeLists.txt").read_text()
    assert f"project({PKG})" in cmake and "rosidl_generate_interfaces(" in cmake
    assert "DEPENDENCIES std_msgs action_msgs" in cmake
    files = sorted(str(p.relative_to(root)) for p in root.glob("[ms][sr][gv]/*.[ms][sr][gv]"))
    files = sorted(files + [str(p.relative_to(root)) for p in root.glob("action/*.action")])
    listed = sorted(line.strip().strip('"') for line in cmake.splitlines()
                    if line.strip().startswith('"'))
    assert files == listed


def test_find_msg_defs_honours_environment(tmp_path, monkeypatch):
    import shutil

    copy = tmp_path / "defs"
    shutil.copytree(find_msg_defs(), copy)
    monkeypatch.setenv("BIPED_OPT_MSG_DEFS", str(copy))
    assert find_msg_defs() == copy
    monkeypatch.setenv("BIPED_OPT_MSG_DEFS", str(tmp_path / "missing"))
    monkeypatch.setattr("biped_opt.interface_defs._candidates", lambda: [tmp_path / "missing"])
    with pytest.raises(InterfaceError, match="BIPED_OPT_MSG_DEFS"):
        find_msg_defs()


def test_the_vendored_standard_keeps_its_names_constants_and_defaults(ifc):
    """simulation_interfaces, vendored as published: rmw_cyclonedds' type names, the
    constants of its definitions, rclpy's field defaults (``uint64 steps 1``), and the same
    CDR bytes as rosbags makes from the same definition."""
    root = find_msg_defs() / "vendor" / "simulation_interfaces"
    assert (root / "LICENSE").read_text().lstrip().startswith("Apache License")
    step = ifc.services["simulation_interfaces/srv/StepSimulation"]
    assert step.RequestWire.__idl_typename__ == \
        "simulation_interfaces::srv::dds_::StepSimulation_Request_"
    assert step.Request().steps == 1  # (the definition's default, as rclpy gives it)
    result = ifc.message_class("simulation_interfaces/msg/Result")
    assert (result.RESULT_FEATURE_UNSUPPORTED, result.RESULT_OK, result.RESULT_NOT_FOUND,
            result.RESULT_INCORRECT_STATE, result.RESULT_OPERATION_FAILED) == (0, 1, 2, 3, 4)
    spawn = ifc.services["simulation_interfaces/srv/SpawnEntity"]
    assert (spawn.Response.NAME_NOT_UNIQUE, spawn.Response.INVALID_POSE) == (101, 109)
    assert "simulation_interfaces/action/SimulateSteps" in ifc.actions
    # the project's own namespaces keep only the project's types
    from biped_opt import ros

    assert not hasattr(ros.srvs, "StepSimulation") and ros.sim_srvs.StepSimulation is step
    # bytes: a state message with every kind of field, against rosbags' serializer
    typename = "simulation_interfaces/msg/EntityState"
    cls = ifc.message_class(typename)
    msg = cls()
    msg.header.stamp.sec, msg.header.frame_id = 7, "world"
    msg.pose.position.z, msg.twist.angular.y = 1.25, -0.5
    ours = bytes(msg.serialize(use_version_2=False))
    theirs_cls = ifc.typestore.types[typename]
    store = ifc.typestore
    theirs = store.serialize_cdr(store.deserialize_cdr(ours, typename), typename)
    assert ours == bytes(theirs) and isinstance(store.deserialize_cdr(ours, typename),
                                                theirs_cls)
