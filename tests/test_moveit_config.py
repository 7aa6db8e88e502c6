"""The MoveIt 2 configuration package moveit_config/ (eezybot_moveit_config), checked
file by file against the robot it describes: urdf/eezybot.urdf and config/arm.yaml.

No MoveIt here: every file is parsed (XML, YAML, the launch file with `ast`, the
CMakeLists install rules) and compared with the URDF, arm.yaml, the Rust kinematics'
passive-joint relations and the outputs of the package's two generator scripts, run
afresh. Nothing is timed."""
import ast
import importlib.util
import itertools
import math
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

REPO = Path(__file__).resolve().parent.parent
PKG = REPO / "moveit_config"
PKG_NAME = "eezybot_moveit_config"
URDF = REPO / "urdf" / "eezybot.urdf"
ARM_YAML = REPO / "config" / "arm.yaml"
SRDF = PKG / "config" / "eezybot_arm_mk2.srdf"
LAUNCH = PKG / "launch" / "move_group.launch.py"
GENERATOR = PKG / "scripts" / "generate_joint_limits.py"
COLLISIONS = PKG / "scripts" / "compute_disabled_collisions.py"

ARM_JOINTS = ["base_joint", "shoulder_joint", "elbow_joint"]
GRIPPER_JOINT = "gripper_joint"
# arm.yaml's keys for each joint: (limits_deg, servos/motion)
ARM_KEYS = {"base_joint": "base", "shoulder_joint": "shoulder", "elbow_joint": "elbow"}
# what compute_ik serves (issue 21): controller -> (type, action_ns, joints)
# the controllers MoveIt executes with: name -> (the type compute_ik's list_controllers
# gives, for which moveit_ros_control_interface has a handle, and the joints)
CONTROLLERS = {
    "arm_controller": ("joint_trajectory_controller/JointTrajectoryController", ARM_JOINTS),
    "gripper_controller": ("position_controllers/GripperActionController", [GRIPPER_JOINT]),
}
# compute_ik's start pose: ArmState::default() = ArmJoints::HOME, claw closed
HOME = {"base_joint": 0.0, "shoulder_joint": math.pi / 2, "elbow_joint": -math.pi / 2}


# ---------------------------------------------------------------------------------------
# the robot: URDF and arm.yaml

def urdf():
    root = ET.parse(URDF).getroot()
    joints = {}
    for j in root.findall("joint"):
        lim, mimic = j.find("limit"), j.find("mimic")
        joints[j.get("name")] = {
            "type": j.get("type"),
            "parent": j.find("parent").get("link"),
            "child": j.find("child").get("link"),
            "limits": None if lim is None else (float(lim.get("lower")), float(lim.get("upper"))),
            "mimic": None if mimic is None else mimic.get("joint"),
            "mimic_rel": None if mimic is None else (
                mimic.get("joint"), float(mimic.get("multiplier", 1)), float(mimic.get("offset", 0))),
            "xyz": [float(v) for v in (j.find("origin").get("xyz") if j.find("origin") is not None else "0 0 0").split()],
        }
    links = {link.get("name"): link for link in root.findall("link")}
    return root.get("name"), joints, links


ROBOT, JOINTS, LINKS = urdf()
ARM = yaml.safe_load(ARM_YAML.read_text(encoding="utf-8"))
MOVABLE = {n for n, j in JOINTS.items() if j["type"] != "fixed"}
MIMIC = {n for n, j in JOINTS.items() if j["mimic"]}
ACTUATED = ARM_JOINTS + [GRIPPER_JOINT]
PASSIVE = MOVABLE - MIMIC - set(ACTUATED)
# issue 21: the linkage joints that follow one actuated joint linearly are URDF mimic
# joints (leader, multiplier, offset); the others follow shoulder + elbow and stay passive
LINKAGE_MIMIC = {
    "drive_link_joint": ("elbow_joint", -1.0, 0.0),
    "level_link_joint": ("shoulder_joint", 1.0, 0.0),
    "triangle_joint": ("shoulder_joint", -1.0, 0.0),
}
# the IK tip of group `arm`: a fixed frame on the forearm at the wrist pivot
IK_TIP = "wrist_pivot"


def rad_limits(key):
    lo, hi = ARM["limits_deg"][key]
    return math.radians(lo), math.radians(hi)


def load_script(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_robot_is_what_this_module_assumes():
    """The facts the other tests take from the brief hold in the URDF."""
    assert set(ACTUATED) <= MOVABLE
    assert MIMIC == {"gripper_mimic_joint"} | set(LINKAGE_MIMIC)
    assert PASSIVE == {"wrist_joint", "crank_joint", "upper_link_joint"}
    for name, rel in LINKAGE_MIMIC.items():
        assert JOINTS[name]["mimic_rel"] == rel, name


# ---------------------------------------------------------------------------------------
# every file of the package is parsed by one of the tests below

def parsed_by_kind(path):
    rel = path.relative_to(PKG).as_posix()
    if rel == "CMakeLists.txt":
        return cmake_commands(path.read_text(encoding="utf-8"))
    if path.suffix in (".xml", ".srdf"):
        return ET.parse(path)
    if path.suffix in (".yaml", ".rviz") or path.name == ".setup_assistant":
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    if path.suffix == ".py":
        return ast.parse(path.read_text(encoding="utf-8"))
    if path.suffix == ".md":
        return path.read_text(encoding="utf-8")
    raise AssertionError(f"{rel}: no test parses this kind of file")


def package_files():
    return sorted(p for p in PKG.rglob("*") if p.is_file() and "__pycache__" not in p.parts)


def test_every_file_of_the_package_parses():
    files = package_files()
    names = {p.relative_to(PKG).as_posix() for p in files}
    for needed in ("package.xml", "CMakeLists.txt", "README.md", "config/eezybot_arm_mk2.srdf",
                   "config/kinematics.yaml", "config/joint_limits.yaml",
                   "config/moveit_controllers.yaml", "config/moveit.rviz",
                   "launch/move_group.launch.py", "scripts/generate_joint_limits.py",
                   "scripts/compute_disabled_collisions.py"):
        assert needed in names, f"moveit_config/{needed} is missing"
    for path in files:
        assert parsed_by_kind(path), f"{path} is empty"


# ---------------------------------------------------------------------------------------
# package.xml and CMakeLists.txt

def cmake_commands(text):
    """[(command, [arguments])] of a CMakeLists, comments dropped, quotes removed."""
    text = re.sub(r"#[^\n]*", "", text)
    out = []
    for m in re.finditer(r"([A-Za-z_][A-Za-z0-9_]*)\s*\(([^()]*(?:\([^()]*\)[^()]*)*)\)", text):
        out.append((m.group(1).lower(), [a.strip('"') for a in re.findall(r'"[^"]*"|[^\s]+', m.group(2))]))
    return out


def cmake_installs():
    """What CMakeLists.txt installs: {destination under share/<pkg>: [source paths]},
    directories as (dir, True), files as (file, False)."""
    commands = cmake_commands((PKG / "CMakeLists.txt").read_text(encoding="utf-8"))
    variables = {"CMAKE_CURRENT_SOURCE_DIR": str(PKG), "PROJECT_NAME": PKG_NAME}

    def expand(s):
        return re.sub(r"\$\{(\w+)\}", lambda m: variables[m.group(1)], s)

    installed = []
    for cmd, args in commands:
        if cmd == "set" and len(args) >= 2:
            variables[args[0]] = expand(args[1])
        if cmd == "install":
            kind = args[0]
            assert kind in ("FILES", "DIRECTORY", "PROGRAMS"), args
            dest = expand(args[args.index("DESTINATION") + 1])
            prefix = f"share/{PKG_NAME}"
            assert dest == prefix or dest.startswith(prefix + "/"), f"installs outside share/{PKG_NAME}: {dest}"
            for src in args[1:args.index("DESTINATION")]:
                path = Path(expand(src))
                path = path if path.is_absolute() else PKG / path
                installed.append((dest[len(prefix):].strip("/"), path.resolve(), kind == "DIRECTORY"))
    return commands, installed


def installed_paths():
    """Relative paths in share/<pkg> after `colcon build` -> source file."""
    _, installed = cmake_installs()
    out = {}
    for dest, src, is_dir in installed:
        assert src.exists(), f"CMakeLists.txt installs {src}, which does not exist"
        if is_dir:
            for f in src.rglob("*"):
                if f.is_file():
                    out[str(Path(dest, src.name, f.relative_to(src)).as_posix()).lstrip("/")] = f
        else:
            out[str(Path(dest, src.name).as_posix()).lstrip("/")] = src
    return out


def test_package_xml_is_an_ament_cmake_format_3_package():
    root = ET.parse(PKG / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == PKG_NAME
    assert [e.text for e in root.findall("buildtool_depend")] == ["ament_cmake"]
    assert root.find("export/build_type").text == "ament_cmake"
    for tag in ("version", "description", "maintainer", "license"):
        assert (root.findtext(tag) or "").strip(), f"package.xml has no <{tag}>"
    commands, _ = cmake_installs()
    project = [args for cmd, args in commands if cmd == "project"]
    assert project and project[0][0] == PKG_NAME, "CMakeLists project() must be the package name"
    assert ("find_package", ["ament_cmake", "REQUIRED"]) in commands
    assert any(cmd == "ament_package" for cmd, _ in commands)


def exec_depends():
    root = ET.parse(PKG / "package.xml").getroot()
    return {e.text for tag in ("exec_depend", "depend") for e in root.findall(tag)}


def test_package_xml_depends_on_every_plugin_the_config_names():
    deps = exec_depends()
    kin = yaml.safe_load((PKG / "config" / "kinematics.yaml").read_text())
    plugin_pkg = {"kdl_kinematics_plugin": "moveit_kinematics", "pick_ik": "pick_ik",
                  "cached_ik_kinematics_plugin": "moveit_kinematics"}
    for group, cfg in kin.items():
        assert plugin_pkg[cfg["kinematics_solver"].split("/")[0]] in deps
    ctl = yaml.safe_load((PKG / "config" / "moveit_controllers.yaml").read_text())
    assert ctl["moveit_controller_manager"].split("/")[0] in deps
    for needed in ("moveit_ros_move_group", "moveit_configs_utils", "rviz2", "moveit_ros_visualization",
                   "moveit_planners_ompl", "launch_ros"):
        assert needed in deps, f"package.xml lacks <exec_depend>{needed}</exec_depend>"


def test_cmakelists_installs_the_config_the_launch_and_the_repositorys_urdf():
    files = installed_paths()
    for rel in ("config/eezybot_arm_mk2.srdf", "config/kinematics.yaml", "config/joint_limits.yaml",
                "config/moveit_controllers.yaml", "config/moveit.rviz", "launch/move_group.launch.py"):
        assert rel in files, f"CMakeLists.txt does not install {rel}"
    assert files.get("urdf/eezybot.urdf") == URDF.resolve(), "the installed URDF must be the repository's"


# ---------------------------------------------------------------------------------------
# the launch file

def launch_tree():
    return ast.parse(LAUNCH.read_text(encoding="utf-8"))


def calls(tree, name):
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call)
            and ((isinstance(n.func, ast.Name) and n.func.id == name)
                 or (isinstance(n.func, ast.Attribute) and n.func.attr == name))]


def kwarg(call, key):
    for k in call.keywords:
        if k.arg == key:
            return k.value
    return None


def constants(tree):
    """Module-level NAME = "string" assignments."""
    out = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            for t in node.targets:
                out[t.id] = node.value.value
    return out


def string_of(node, consts):
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.Name) and node.id in consts:
        return consts[node.id]
    return None


def test_launch_starts_only_move_group_and_rviz():
    tree = launch_tree()
    consts = constants(tree)
    started = set()
    for node in calls(tree, "Node"):
        started.add((string_of(kwarg(node, "package"), consts), string_of(kwarg(node, "executable"), consts)))
    assert started == {("moveit_ros_move_group", "move_group"), ("rviz2", "rviz2")}
    # nothing of ros2_control, robot_state_publisher or fake controllers, by any means: no
    # string or name of the code (docstrings aside) mentions them
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, (ast.Module, ast.FunctionDef)) and n.body
                  and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    words = [n.value for n in ast.walk(tree)
             if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docstrings]
    words += [n.id for n in ast.walk(tree) if isinstance(n, ast.Name)]
    words += [n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)]
    words += [a.name for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom)) for a in n.names]
    words += [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    for forbidden in ("ros2_control", "controller_manager", "spawner", "robot_state_publisher",
                      "joint_state_publisher", "demo_launch", "rsp_launch", "spawn_controllers",
                      "mock_components", "fake"):
        hits = [w for w in words if forbidden in w]
        assert not hits, f"the launch file uses {hits}"
    for pkg, _ in started:
        assert pkg in exec_depends(), f"{pkg} is started but not an exec_depend"
    # RViz only on request
    rviz = [n for n in calls(tree, "Node") if string_of(kwarg(n, "package"), consts) == "rviz2"][0]
    assert kwarg(rviz, "condition") is not None


def test_launch_declares_use_rviz_and_namespace_and_uses_them():
    tree = launch_tree()
    declared = {string_of(c.args[0], {}) for c in calls(tree, "DeclareLaunchArgument")}
    assert {"use_rviz", "namespace"} <= declared
    used = {string_of(c.args[0], {}) for c in calls(tree, "LaunchConfiguration")}
    assert declared <= used, f"declared but never used: {declared - used}"


def test_launch_builds_the_config_from_this_package_with_managed_controllers():
    tree = launch_tree()
    consts = constants(tree)
    builder = calls(tree, "MoveItConfigsBuilder")
    assert len(builder) == 1
    assert string_of(kwarg(builder[0], "package_name"), consts) == PKG_NAME
    srdf_root = ET.parse(SRDF).getroot()
    assert string_of(builder[0].args[0], consts) == srdf_root.get("name") == ROBOT
    traj = calls(tree, "trajectory_execution")
    assert len(traj) == 1
    manage = kwarg(traj[0], "moveit_manage_controllers")
    assert isinstance(manage, ast.Constant) and manage.value is True
    # move_group finds the controller manager in the graph's namespace
    assert '"ros_control_namespace": "/" + (namespace or "")' in (PKG / "launch" / "move_group.launch.py").read_text()
    # every file the builder is given is in the package and installed where it is looked up
    files = installed_paths()
    for method in ("robot_description_semantic", "robot_description_kinematics", "joint_limits",
                   "trajectory_execution"):
        (call,) = calls(tree, method)
        rel = string_of(kwarg(call, "file_path"), consts)
        assert rel and rel in files, f"{method}: {rel} is not installed"


def test_every_path_the_launch_file_names_is_installed():
    tree = launch_tree()
    consts = constants(tree)
    files = installed_paths()
    dirs = {Path(rel).parts[0] for rel in files}
    paths = [v for v in consts.values() if re.match(r"^(config|launch|urdf)/", v)]
    assert {"config/eezybot_arm_mk2.srdf", "urdf/eezybot.urdf", "config/moveit.rviz"} <= set(paths)
    for rel in paths:
        assert Path(rel).parts[0] in dirs, f"the launch file uses {rel}: its directory is not installed"
        assert rel in files, f"the launch file uses {rel}, which CMakeLists.txt does not install"


def test_setup_assistant_file_points_at_installed_files():
    cfg = yaml.safe_load((PKG / ".setup_assistant").read_text())["moveit_setup_assistant_config"]
    files = installed_paths()
    assert cfg["urdf"]["package"] == PKG_NAME
    assert cfg["urdf"]["relative_path"] in files
    assert cfg["srdf"]["relative_path"] in files
    assert ".setup_assistant" in files


# ---------------------------------------------------------------------------------------
# the SRDF

def srdf():
    return ET.parse(SRDF).getroot()


def parent_joint(link):
    return next((n for n, j in JOINTS.items() if j["child"] == link), None)


def group_joints(root, name):
    """The joints of an SRDF group as MoveIt's RobotModel::addJointModelGroup collects
    them: <chain> (every joint from the tip up to the base, fixed ones included) and
    <joint>; <link> and subgroups are not used here. Mimic joints are not added."""
    (group,) = [g for g in root.findall("group") if g.get("name") == name]
    assert not group.findall("link") and not group.findall("group"), f"{name}: chains and joints only"
    out = []
    for chain in group.findall("chain"):
        base, link, cj = chain.get("base_link"), chain.get("tip_link"), []
        while link != base:
            j = parent_joint(link)
            assert j is not None, f"{name}: {base} is not above {chain.get('tip_link')}"
            cj.append(j)
            link = JOINTS[j]["parent"]
        out += reversed(cj)
    out += [j.get("name") for j in group.findall("joint")]
    assert len(out) == len(set(out)), f"{name}: a joint twice"
    return out


def active_joints(root, name):
    """MoveIt's active joints of a group: movable and not mimic."""
    return [j for j in group_joints(root, name) if j in MOVABLE and j not in MIMIC]


def dfs_index(joint):
    """Depth-first order of the URDF tree (MoveIt sorts a group's joints so)."""
    out = []

    def walk(link):
        for n, j in JOINTS.items():
            if j["parent"] == link:
                out.append(n)
                walk(j["child"])
    walk(next(iter({j["parent"] for j in JOINTS.values()} - {j["child"] for j in JOINTS.values()})))
    return out.index(joint)


def is_chain(joints):
    """JointModelGroup's chain test: one root among the active joints, and each joint
    (fixed and mimic ones included), in depth-first order, right below the previous one
    (only fixed joints between)."""
    order = sorted(joints, key=dfs_index)
    active = [j for j in order if j in MOVABLE and j not in MIMIC]
    roots = [j for j in active if not any(a != j and a in ancestors(j) for a in active)]
    if len(roots) != 1:
        return False
    for prev, joint in zip(order, order[1:]):
        p = parent_joint(JOINTS[joint]["parent"])
        while p is not None and p != prev and JOINTS[p]["type"] == "fixed":
            p = parent_joint(JOINTS[p]["parent"])
        if p != prev:
            return False
    return True


def ancestors(joint):
    out, p = [], parent_joint(JOINTS[joint]["parent"])
    while p is not None:
        out.append(p)
        p = parent_joint(JOINTS[p]["parent"])
    return out


def last_link(joints):
    """A group's last link (MoveIt's kinematics plugin loader takes it as the IK tip):
    the children of its joints, in depth-first order."""
    return JOINTS[max(joints, key=dfs_index)]["child"]


def test_srdf_names_only_joints_and_links_of_the_urdf():
    root = srdf()
    assert root.get("name") == ROBOT
    for el in root.iter():
        for attr in ("link1", "link2", "parent_link", "link", "base_link", "tip_link", "child_link"):
            if el.get(attr) is not None:
                assert el.get(attr) in LINKS, f"SRDF <{el.tag} {attr}={el.get(attr)}>: no such URDF link"
        if el.tag in ("joint", "passive_joint"):
            assert el.get("name") in JOINTS, f"SRDF <{el.tag} name={el.get('name')}>: no such URDF joint"


def test_arm_group_is_exactly_the_actuated_arm_joints():
    assert sorted(active_joints(srdf(), "arm")) == sorted(ARM_JOINTS)
    # nothing else moves in it: the rest is the fixed joint to the IK tip
    others = set(group_joints(srdf(), "arm")) - set(ARM_JOINTS)
    assert all(JOINTS[j]["type"] == "fixed" for j in others), others


def test_arm_group_is_a_chain_for_kdl():
    """MoveIt's JointModelGroup is a chain when each joint's parent (through fixed joints
    only) is the previous one; KDL refuses a group that is not."""
    joints = group_joints(srdf(), "arm")
    assert is_chain(joints)
    order = sorted(joints, key=dfs_index)
    for parent, child in zip(order, order[1:]):
        up = parent_joint(JOINTS[child]["parent"])
        while JOINTS[up]["type"] == "fixed" and up != parent:
            up = parent_joint(JOINTS[up]["parent"])
        assert up == parent, f"{child} does not follow {parent}: not a chain"
    # the chain test can fail: with the linkage's mimic joints in it (which would make
    # MoveIt update them in every planned state) the group is no chain
    assert not is_chain(joints + ["drive_link_joint"])
    assert not is_chain(joints + ["level_link_joint", "triangle_joint"])
    assert not is_chain(joints + ["wrist_joint"] + ["gripper_joint"])


def test_arm_group_ends_at_the_wrist_pivot_frame():
    """The group is the chain base_link -> wrist_pivot, so its last link, the KDL tip, is
    the wrist pivot: a fixed frame on the forearm at wrist_joint's origin."""
    (group,) = [g for g in srdf().findall("group") if g.get("name") == "arm"]
    (chain,) = group.findall("chain")
    assert (chain.get("base_link"), chain.get("tip_link")) == ("base_link", IK_TIP)
    assert last_link(group_joints(srdf(), "arm")) == IK_TIP
    j = JOINTS[parent_joint(IK_TIP)]
    assert j["type"] == "fixed" and j["parent"] == "forearm"
    assert j["xyz"] == JOINTS["wrist_joint"]["xyz"] and JOINTS["wrist_joint"]["parent"] == "forearm"
    assert LINKS[IK_TIP].find("collision") is None and LINKS[IK_TIP].find("visual") is None
    # and it is a leaf: nothing hangs below it
    assert not any(jj["parent"] == IK_TIP for jj in JOINTS.values())


def test_tool0_is_the_wrist_pivot_plus_the_level_tool_offset():
    """What the README tells users: tool0 = wrist_pivot + tool_dx (0.0393 m) along the
    arm's horizontal direction, in every state (the URDF's forward kinematics)."""
    tool_dx = ARM["geometry"]["tool_dx_m"]
    assert tool_dx == 0.0393
    script = load_script(COLLISIONS)
    links, joints = script.load_urdf(URDF)
    samples = script.samples_from(ARM_YAML, steps=7)
    n = len(samples["base_joint"])
    pose = script.forward(joints, script.joint_values(samples, joints), n)
    theta = samples["base_joint"]
    d = pose["tool0"][1] - pose[IK_TIP][1]
    assert np.max(np.abs(d[:, 0] - tool_dx * np.cos(theta))) < 1e-12
    assert np.max(np.abs(d[:, 1] - tool_dx * np.sin(theta))) < 1e-12
    assert np.max(np.abs(d[:, 2])) < 1e-12
    # the README's formula for a tool0 target, and its home numbers
    for k in range(n):
        x, y, z = pose["tool0"][1][k]
        r = math.hypot(x, y)
        assert (x * (1 - tool_dx / r), y * (1 - tool_dx / r), z) == pytest.approx(tuple(pose[IK_TIP][1][k]), abs=1e-12)
    home = script.forward(joints, script.joint_values({k: np.array([v]) for k, v in script.HOME.items()}, joints), 1)
    assert tuple(home[IK_TIP][1][0]) == pytest.approx((0.147, 0.0, 0.229), abs=1e-12)
    assert tuple(home["tool0"][1][0]) == pytest.approx((0.1863, 0.0, 0.229), abs=1e-12)
    text = (PKG / "README.md").read_text(encoding="utf-8")
    assert "(0.147, 0, 0.229)" in text and "(0.1863, 0, 0.229)" in text and "0.0393" in text


def test_gripper_group_has_the_claw_and_its_mimic():
    joints = group_joints(srdf(), "gripper")
    assert GRIPPER_JOINT in joints
    # a URDF mimic joint outside the group would not follow gripper_joint in planned states
    for name in joints:
        assert name == GRIPPER_JOINT or JOINTS[name]["mimic"] == GRIPPER_JOINT
    assert {n for n in MIMIC if JOINTS[n]["mimic"] == GRIPPER_JOINT} <= set(joints)


def test_passive_joints_are_exactly_the_unmodelled_linkage_joints():
    root = srdf()
    passive = [p.get("name") for p in root.findall("passive_joint")]
    assert len(passive) == len(set(passive))
    assert set(passive) == PASSIVE
    # none is planned: no group holds a passive joint
    for g in root.findall("group"):
        assert not set(group_joints(root, g.get("name"))) & PASSIVE
    # a mimic joint is never passive: MoveIt sets it from its source joint
    assert not set(passive) & MIMIC


def test_single_joint_linkage_relations_are_urdf_mimic_tags():
    """Issue 21: every linkage joint that is linear in one actuated joint carries the
    <mimic> of that relation (offset 0), and only those: the others need two joints."""
    script = load_script(COLLISIONS)
    for name, terms in script.PASSIVE.items():
        if len(terms) == 1:
            ((leader, mult),) = terms.items()
            assert JOINTS[name]["mimic_rel"] == (leader, mult, 0.0), name
        else:
            assert JOINTS[name]["mimic_rel"] is None, name
    assert {n for n, t in script.PASSIVE.items() if len(t) == 1} == set(LINKAGE_MIMIC)
    links, joints = script.load_urdf(URDF)
    assert script.mimic_tag_problems(joints) == []
    # the check can fail
    bad = {k: dict(v) for k, v in joints.items()}
    bad["drive_link_joint"]["mimic"] = ("elbow_joint", -1.0, 0.01)
    bad["level_link_joint"]["mimic"] = ("elbow_joint", 1.0, 0.0)
    assert len(script.mimic_tag_problems(bad)) == 2


def test_mimic_joint_limits_hold_whenever_their_leader_is_within_its_own():
    """MoveIt checks every joint's bounds in a state (a mimic joint included): the range
    of multiplier * leader + offset over the leader's limits lies within the mimic
    joint's own URDF limits."""
    for name in MIMIC:
        leader, mult, off = JOINTS[name]["mimic_rel"]
        lo, hi = JOINTS[leader]["limits"]
        ends = sorted((mult * lo + off, mult * hi + off))
        mlo, mhi = JOINTS[name]["limits"]
        assert mlo <= ends[0] + 1e-12 and ends[1] <= mhi + 1e-12, (name, ends, (mlo, mhi))


def test_passive_joints_are_the_linear_relations_of_the_rust_kinematics():
    """PASSIVE of compute_disabled_collisions.py (which poses the linkage for the
    collision sampling and which the README's linkage table states) is
    PassiveJoints::from_arm of libs/kinematics, parsed from the Rust source."""
    src = (REPO / "libs" / "kinematics" / "src" / "lib.rs").read_text(encoding="utf-8")
    body = re.search(r"pub fn from_arm\(q: &ArmJoints\) -> PassiveJoints \{(.*?)\n    \}", src, re.S).group(1)
    fields = dict(re.findall(r"(\w+)_rad: ([^,]+),", body))
    assert len(fields) == 6, fields
    alpha, phi = {"shoulder_joint": 1.0}, {"shoulder_joint": 1.0, "elbow_joint": 1.0}

    def coefficients(expr):
        out = {}
        for sign, term in re.findall(r"([+-]?)\s*(alpha|phi)", expr.replace(" ", "")):
            for j, c in (alpha if term == "alpha" else phi).items():
                out[j] = out.get(j, 0.0) + (-c if sign == "-" else c)
        return {j: c for j, c in out.items() if c != 0.0}

    rust = {f"{name}_joint": coefficients(e) for name, e in fields.items()}
    script = load_script(COLLISIONS)
    assert rust == script.PASSIVE
    assert set(script.PASSIVE) == PASSIVE | set(LINKAGE_MIMIC)


def test_the_urdf_loops_close_with_those_relations():
    """The evidence that the passive joints are exactly these linear functions: with them,
    every pin of the open-chain URDF meets its partner and the plates stay level."""
    script = load_script(COLLISIONS)
    links, joints = script.load_urdf(URDF)
    samples = script.samples_from(ARM_YAML, steps=5)
    n = len(samples["base_joint"])
    pose = script.forward(joints, script.joint_values(samples, joints), n)
    errors = script.closure_errors(joints, links, pose)
    assert len(errors) == 5
    for what, err in errors.items():
        assert err < 1e-9, f"{what}: {err}"
    # the mimic tags alone pose their joints (the script lets them override PASSIVE): the
    # loops close with PASSIVE reduced to the two-joint relations, and open with a wrong
    # offset in a tag
    saved = script.PASSIVE
    try:
        script.PASSIVE = {k: v for k, v in saved.items() if k in PASSIVE}
        pose = script.forward(joints, script.joint_values(samples, joints), n)
        for what, err in script.closure_errors(joints, links, pose).items():
            assert err < 1e-9, f"{what}: {err} with the mimic tags"
        for name in LINKAGE_MIMIC:
            bad = {k: dict(v) for k, v in joints.items()}
            leader, mult, _ = bad[name]["mimic"]
            bad[name]["mimic"] = (leader, mult, 0.01)
            pose = script.forward(bad, script.joint_values(samples, bad), n)
            assert max(script.closure_errors(bad, links, pose).values()) > 1e-3, name
    finally:
        script.PASSIVE = saved
    # and a wrong relation does not close (the check can fail)
    wrong = dict(script.PASSIVE, wrist_joint={"shoulder_joint": -1.0})
    try:
        script.PASSIVE, saved = wrong, script.PASSIVE
        pose = script.forward(joints, script.joint_values(samples, joints), n)
        assert script.closure_errors(joints, links, pose)["front_plate level (|x_z|)"] > 0.1
    finally:
        script.PASSIVE = saved


def group_states(root):
    out = {}
    for s in root.findall("group_state"):
        out[(s.get("group"), s.get("name"))] = {j.get("name"): float(j.get("value")) for j in s.findall("joint")}
    return out


def test_named_states_are_complete_and_inside_every_limit():
    root = srdf()
    states = group_states(root)
    assert ("arm", "home") in states
    for (group, name), values in states.items():
        assert set(values) == set(active_joints(root, group)), (group, name)
        for joint, v in values.items():
            lo, hi = JOINTS[joint]["limits"]
            assert lo - 1e-9 <= v <= hi + 1e-9, f"{name}: {joint} = {v} outside the URDF's {lo} .. {hi}"
        if group == "arm":
            for joint, key in ARM_KEYS.items():
                lo, hi = rad_limits(key)
                assert lo - 1e-9 <= values[joint] <= hi + 1e-9, f"{name}: {joint} outside arm.yaml"
            lo, hi = rad_limits("forearm_elevation")
            phi = values["shoulder_joint"] + values["elbow_joint"]
            assert lo - 1e-9 <= phi <= hi + 1e-9, f"{name}: forearm elevation {math.degrees(phi)} deg"
        if group == "gripper":
            assert 0.0 <= values[GRIPPER_JOINT] <= ARM["geometry"]["gripper_open_rad"] + 1e-12


def test_home_is_compute_ik_start_pose():
    src = (REPO / "libs" / "kinematics" / "src" / "lib.rs").read_text(encoding="utf-8")
    home = re.search(r"pub const HOME: ArmJoints = ArmJoints \{(.*?)\};", src, re.S).group(1)
    rust = dict(re.findall(r"(\w+)_rad: ([\w.:-]+),", home))
    value = {"0.0": 0.0, "FRAC_PI_2": math.pi / 2, "-FRAC_PI_2": -math.pi / 2}
    assert {f"{k}_joint": value[v] for k, v in rust.items()} == HOME
    eezybot = (REPO / "nodes" / "compute_ik" / "src" / "eezybot.rs").read_text(encoding="utf-8")
    assert re.search(r"fn start\(&self\) -> ArmState \{\s*ArmState::default\(\)", eezybot)
    got = group_states(srdf())[("arm", "home")]
    for joint, v in HOME.items():
        assert got[joint] == pytest.approx(v, abs=1e-9)
    closed = [v for (g, _), v in group_states(srdf()).items() if g == "gripper" and v[GRIPPER_JOINT] == 0.0]
    assert closed, "a gripper state with the claw closed (the start state)"


def test_end_effector_is_the_gripper_group_at_a_urdf_link():
    root = srdf()
    (eef,) = root.findall("end_effector")
    assert eef.get("group") == "gripper"
    assert eef.get("parent_link") in LINKS
    # MoveIt refuses a parent_group that does not contain the parent link
    if eef.get("parent_group"):
        group = group_joints(root, eef.get("parent_group"))
        assert eef.get("parent_link") in {JOINTS[j]["child"] for j in group}
    else:
        # RViz then puts the arm's drag handle on the arm's last link, the IK tip
        arm = group_joints(root, "arm")
        assert eef.get("parent_link") not in {JOINTS[j]["child"] for j in arm}
    # the claw's links hang below the parent link
    link, up = JOINTS[GRIPPER_JOINT]["parent"], []
    while link:
        up.append(link)
        link = next((j["parent"] for j in JOINTS.values() if j["child"] == link), None)
    tool = eef.get("parent_link")
    assert tool in up or JOINTS[next(n for n, j in JOINTS.items() if j["child"] == tool)]["parent"] in up


def disabled_pairs(root):
    return {tuple(sorted((d.get("link1"), d.get("link2")))): d.get("reason") for d in root.findall("disable_collisions")}


def test_disabled_collision_pairs_name_two_links_with_geometry():
    root = srdf()
    elements = root.findall("disable_collisions")
    pairs = disabled_pairs(root)
    assert len(pairs) == len(elements), "a pair is disabled twice"
    for (a, b), reason in pairs.items():
        assert a != b
        assert a in LINKS and b in LINKS
        assert LINKS[a].find("collision") is not None and LINKS[b].find("collision") is not None
        assert reason in ("Adjacent", "Never", "Always", "Default", "User")
    # Adjacent means joined by a joint (through links without geometry)
    for (a, b), reason in pairs.items():
        if reason == "Adjacent":
            assert any({j["parent"], j["child"]} == {a, b} for j in JOINTS.values()), (a, b)


def test_disabled_collision_pairs_are_what_the_script_computes_now():
    script = load_script(COLLISIONS)
    result, sometimes, n, _ = script.classify(URDF, ARM_YAML)
    assert n > 5000
    assert disabled_pairs(srdf()) == {tuple(sorted(p)): r for p, r in result.items()}
    # the pairs left enabled are really enabled, and every geometry pair is decided
    geometry = sorted(l for l, el in LINKS.items() if el.find("collision") is not None)
    all_pairs = set(itertools.combinations(geometry, 2))
    assert set(result) | set(sometimes) == all_pairs
    assert not set(sometimes) & set(disabled_pairs(srdf()))


def test_collision_check_finds_a_real_contact():
    """The sampler is not blind: the main arm against the forearm (adjacent, so disabled
    for MoveIt) overlaps in every sample, and the claw meets the base at low reaches."""
    script = load_script(COLLISIONS)
    links, joints = script.load_urdf(URDF)
    samples = script.samples_from(ARM_YAML, steps=9)
    n = len(samples["base_joint"])
    boxes = script.world_boxes(links, script.forward(joints, script.joint_values(samples, joints), n))
    assert script.link_collisions(boxes, "main_arm", "forearm").all()
    assert script.link_collisions(boxes, "base_link", "front_plate").any()
    assert not script.link_collisions(boxes, "base_link", "upper_link").any()


# ---------------------------------------------------------------------------------------
# kinematics.yaml

def test_kinematics_is_position_only_ik_for_the_arm():
    kin = yaml.safe_load((PKG / "config" / "kinematics.yaml").read_text())
    groups = {g.get("name") for g in srdf().findall("group")}
    assert set(kin) <= groups
    arm = kin["arm"]
    assert arm["kinematics_solver"] == "kdl_kinematics_plugin/KDLKinematicsPlugin"
    assert arm["position_only_ik"] is True
    assert 0 < arm["kinematics_solver_timeout"] <= 1.0
    assert 0 < arm["kinematics_solver_search_resolution"] <= 0.1


# ---------------------------------------------------------------------------------------
# joint_limits.yaml

def generated(tmp_path, arm_config=ARM_YAML, *extra):
    out = tmp_path / "joint_limits.yaml"
    subprocess.run([sys.executable, str(GENERATOR), "--arm-config", str(arm_config), "-o", str(out), *extra],
                   check=True, capture_output=True, text=True)
    return out.read_text(encoding="utf-8")


def test_joint_limits_yaml_is_the_generators_output_from_arm_yaml(tmp_path):
    shipped = (PKG / "config" / "joint_limits.yaml").read_text(encoding="utf-8")
    assert shipped == generated(tmp_path), (
        "config/joint_limits.yaml is stale: run python3 moveit_config/scripts/generate_joint_limits.py")
    assert shipped.startswith("# GENERATED by moveit_config/scripts/generate_joint_limits.py")


def joint_limits():
    return yaml.safe_load((PKG / "config" / "joint_limits.yaml").read_text(encoding="utf-8"))


def test_joint_limits_cover_the_actuated_joints_with_every_flag():
    jl = joint_limits()
    assert 0 < jl["default_velocity_scaling_factor"] <= 1
    assert 0 < jl["default_acceleration_scaling_factor"] <= 1
    assert set(jl["joint_limits"]) == set(ACTUATED)
    for joint, lim in jl["joint_limits"].items():
        assert joint in JOINTS and JOINTS[joint]["type"] == "revolute"
        assert lim["has_position_limits"] is True
        assert lim["has_velocity_limits"] is True and lim["max_velocity"] > 0
        assert lim["has_acceleration_limits"] is True and lim["max_acceleration"] > 0


def test_position_limits_are_arm_yaml_in_radians_and_the_urdfs():
    jl = joint_limits()["joint_limits"]
    expected = {j: rad_limits(k) for j, k in ARM_KEYS.items()}
    expected[GRIPPER_JOINT] = (0.0, ARM["geometry"]["gripper_open_rad"])
    for joint, (lo, hi) in expected.items():
        got = jl[joint]
        assert got["min_position"] == pytest.approx(lo, abs=1e-8), joint
        assert got["max_position"] == pytest.approx(hi, abs=1e-8), joint
        # never wider than arm.yaml allows
        assert got["min_position"] >= lo - 1e-12 and got["max_position"] <= hi + 1e-12, joint
        # the URDF (rounded to 1e-6 rad by make_urdf.py) agrees
        ulo, uhi = JOINTS[joint]["limits"]
        assert got["min_position"] == pytest.approx(ulo, abs=1e-6), joint
        assert got["max_position"] == pytest.approx(uhi, abs=1e-6), joint


def test_motion_limits_are_the_servos_divided_by_their_gain():
    """Independently of the generator: horn deg/s / |gain| -> rad/s; the base turns at
    half its servo's speed (2:1 gear); the claw's opening 0..1 is gripper_open_rad."""
    jl = joint_limits()["joint_limits"]
    servos, motion = ARM["servos"], ARM["motion"]
    for joint, key in ARM_KEYS.items():
        g = abs(servos[key]["gain"])
        assert jl[joint]["max_velocity"] == pytest.approx(math.radians(motion[key]["max_velocity_deg_s"] / g), abs=1e-8)
        assert jl[joint]["max_acceleration"] == pytest.approx(
            math.radians(motion[key]["max_acceleration_deg_s2"] / g), abs=1e-8)
    assert jl["base_joint"]["max_velocity"] == pytest.approx(jl["shoulder_joint"]["max_velocity"] / 2, abs=1e-8)
    open_rad = ARM["geometry"]["gripper_open_rad"]
    g = abs(servos["gripper"]["gain"])
    assert jl[GRIPPER_JOINT]["max_velocity"] == pytest.approx(motion["gripper"]["max_velocity_deg_s"] / g * open_rad)
    assert jl[GRIPPER_JOINT]["max_acceleration"] == pytest.approx(
        motion["gripper"]["max_acceleration_deg_s2"] / g * open_rad)


def test_generator_follows_arm_yaml(tmp_path):
    """Changing arm.yaml changes the output: a base servo at 200 deg/s and gain -4 makes
    base_joint 50 deg/s; a narrower shoulder limit shows up in radians."""
    arm = yaml.safe_load(ARM_YAML.read_text())
    arm["motion"]["base"]["max_velocity_deg_s"] = 200.0
    arm["servos"]["base"]["gain"] = -4.0
    arm["limits_deg"]["shoulder"] = [50.0, 110.0]
    path = tmp_path / "arm.yaml"
    path.write_text(yaml.safe_dump(arm))
    out = yaml.safe_load(generated(tmp_path, path))["joint_limits"]
    assert out["base_joint"]["max_velocity"] == pytest.approx(math.radians(50.0), abs=1e-8)
    assert out["shoulder_joint"]["min_position"] == pytest.approx(math.radians(50.0), abs=1e-8)
    assert out["shoulder_joint"]["max_position"] == pytest.approx(math.radians(110.0), abs=1e-8)


def test_coupled_option_never_lets_the_forearm_servo_exceed_its_limit(tmp_path):
    out = yaml.safe_load(generated(tmp_path, ARM_YAML, "--coupled"))["joint_limits"]
    phi_v = math.radians(ARM["motion"]["elbow"]["max_velocity_deg_s"] / abs(ARM["servos"]["elbow"]["gain"]))
    sh_v = math.radians(ARM["motion"]["shoulder"]["max_velocity_deg_s"] / abs(ARM["servos"]["shoulder"]["gain"]))
    assert out["shoulder_joint"]["max_velocity"] + out["elbow_joint"]["max_velocity"] <= phi_v + 1e-9
    assert out["shoulder_joint"]["max_velocity"] <= sh_v + 1e-9


# ---------------------------------------------------------------------------------------
# moveit_controllers.yaml

def test_moveit_manages_the_graphs_controllers_through_its_controller_manager():
    cfg = yaml.safe_load((PKG / "config" / "moveit_controllers.yaml").read_text())
    assert cfg["moveit_controller_manager"] == "moveit_ros_control_interface/Ros2ControlManager"
    assert cfg["moveit_manage_controllers"] is True
    # no static controller list: the plugin lists compute_ik's (test_controller_manager.py
    # checks that list: the types below, and these joints' interfaces)
    assert "moveit_simple_controller_manager" not in cfg
    te = cfg["trajectory_execution"]
    assert te["allowed_execution_duration_scaling"] >= 1.0
    assert te["allowed_goal_duration_margin"] >= 0.0
    assert 0.0 < te["allowed_start_tolerance"] <= 0.1


def test_the_controllers_drive_exactly_the_groups_and_every_actuated_joint():
    # the arm controller drives exactly the arm group, the gripper controller the gripper's
    assert sorted(CONTROLLERS["arm_controller"][1]) == sorted(active_joints(srdf(), "arm"))
    assert sorted(CONTROLLERS["gripper_controller"][1]) == sorted(active_joints(srdf(), "gripper"))
    driven = [j for _, joints in CONTROLLERS.values() for j in joints]
    assert sorted(driven) == sorted(ACTUATED)
    for j in driven:
        assert j in JOINTS


# ---------------------------------------------------------------------------------------
# RViz and the README

def test_rviz_config_shows_motion_planning_for_the_arm():
    rviz = yaml.safe_load((PKG / "config" / "moveit.rviz").read_text())
    displays = rviz["Visualization Manager"]["Displays"]
    (mp,) = [d for d in displays if d["Class"] == "moveit_rviz_plugin/MotionPlanning"]
    assert mp["Planning Request"]["Planning Group"] in {g.get("name") for g in srdf().findall("group")}
    assert mp["Robot Description"] == "robot_description"
    # relative topics: they follow the launch file's namespace
    assert not mp["Planning Scene Topic"].startswith("/")
    assert not mp["Planned Path"]["Trajectory Topic"].startswith("/")
    assert rviz["Visualization Manager"]["Global Options"]["Fixed Frame"] in LINKS


def test_readme_tells_how_to_build_launch_and_regenerate():
    text = (PKG / "README.md").read_text(encoding="utf-8")
    for needed in ("colcon build --packages-select eezybot_moveit_config",
                   "ros2 launch eezybot_moveit_config move_group.launch.py",
                   "generate_joint_limits.py", "compute_disabled_collisions.py", "passive"):
        assert needed in text, f"README.md does not mention {needed}"
    for name in PASSIVE | set(LINKAGE_MIMIC):
        assert name in text, f"README.md does not say what MoveIt shows for {name}"
    for name, (leader, mult, off) in LINKAGE_MIMIC.items():
        assert f'<mimic joint="{leader}" multiplier="{mult:g}" offset="{off:g}"/>' in text, name


def test_readme_tells_how_to_give_cartesian_goals_for_the_wrist_pivot():
    text = (PKG / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## Cartesian goals"):text.index("## What MoveIt shows")]
    for needed in ("wrist_pivot", "tool0", "0.0393", "setPositionTarget", "construct_link_constraint",
                   "MotionPlanning", "position-only IK"):
        assert needed in section, f"README.md's Cartesian goals do not mention {needed}"
    kin = (PKG / "config" / "kinematics.yaml").read_text(encoding="utf-8")
    assert "wrist_pivot" in kin
