"""Packaging and ROS conventions: colcon builds (plain and --symlink-install), the manifests and the
dependencies they declare, the ament index of an editable install (``gyro-sim ros-index``), the nodes'
``--help``, the launch file, the parameter files under a namespace, the CLI without rclpy.

ros2cli and launch are not installable from PyPI: ``ros2 run`` is checked the way it resolves an
executable (ament_index_python), the launch file against stub ``launch``/``launch_ros`` modules.
"""
import ast
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import types
from importlib.metadata import distribution
from pathlib import Path

import pytest
import yaml
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
COPY_IGNORE = shutil.ignore_patterns(".git", ".venv", "build", "install", "log", "runs", "__pycache__", "*.egg-info",
                                     ".hypothesis", ".pytest_cache", ".benchmarks", "*.nbi", "*.nbc",
                                     ".mypy_cache", ".ruff_cache")
# what setup.py's data_files install (checked in a colcon install and in a ros-index prefix)
INDEX = "share/ament_index/resource_index/packages/"
DATA_FILES = [INDEX + "gyro_sim", INDEX + "gyro_ctl",
              "share/gyro_sim/package.xml", "share/gyro_ctl/package.xml", "share/gyro_sim/launch/gyro_sim.launch.py",
              "share/gyro_sim/config/simulator.params.yaml", "share/gyro_sim/config/controller.params.yaml",
              "share/gyro_sim/config/foxglove_layout.json",
              "lib/gyro_sim/simulator", "lib/gyro_ctl/controller"]
ROS_MISSING = "needs the ROS 2 Python packages (rclpy): pip install 'gyro_sim[ros]' (or source a ROS 2 install)"


def run(cmd, timeout=120, **kw):
    """Run ``cmd``; its CompletedProcess (text output)."""
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=timeout, **kw)


def manifest(path):
    from catkin_pkg.package import parse_package

    return parse_package(str(path))


def names(deps) -> set:
    return {d.name for d in deps}


# --- the nodes' --help ----------------------------------------------------------------------------

@pytest.mark.parametrize("module", ["gyro_sim.ros.simulator_node", "gyro_ctl.ros.controller_node"])
def test_node_help_exits_without_running(module):
    pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")
    from test_ros import unique_domain

    for flag in ("--help", "-h"):
        # a node that ran would wait for its peer (or simulate 60 s): the bound is generous, not a timing check
        r = run([sys.executable, "-m", module, flag], timeout=60,
                env=dict(os.environ, ROS_DOMAIN_ID=str(unique_domain()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"))
        assert r.returncode == 0, r.stderr
        assert r.stdout.startswith("usage:") and "--ros-args" in r.stdout, r.stdout
        # the parameters the node declares, each with its description
        for name in ("scene", "law", "nu") if "ctl" in module else ("scene", "control_period", "step_ticks"):
            assert re.search(rf"^  {name} ", r.stdout, re.M), (name, r.stdout)


def test_node_main_help_prints_the_usage_and_never_starts_rclpy(monkeypatch, capsys):
    rclpy = pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")
    from gyro_sim.ros.common import node_main, node_usage

    class Started(Exception):
        pass

    def fail(*a, **k):
        raise Started

    monkeypatch.setattr(rclpy, "init", fail)
    usage = node_usage("ros2 run gyro_sim simulator", [("scene", "spinup_thin_shell", "scene name or path"),
                                                       ("rate_factor", 1.0, "simulated s per wall s", (1e-3, 1e4))])
    assert node_main("simulator", fail, fail, ["simulator", "-p", "--help"], usage=usage) == 0
    out = capsys.readouterr().out
    assert out == usage and out.startswith("usage: ros2 run gyro_sim simulator")
    assert re.search(r"^  scene +'spinup_thin_shell' +scene name or path$", out, re.M)
    assert re.search(r"^  rate_factor +1\.0 +simulated s per wall s$", out, re.M)
    with pytest.raises(Started):  # after --ros-args, --help is ROS's (rcl's) argument
        node_main("simulator", fail, fail, ["simulator", "--ros-args", "--help"], usage=usage)


# --- the CLI without rclpy ------------------------------------------------------------------------

@pytest.mark.parametrize("argv,what", [(["run", "free_rotor", "--ros"], "gyro-sim run --ros"),
                                       (["replay", "BAG"], "gyro-sim replay (without --check)")])
def test_cli_without_rclpy(tmp_path, argv, what):
    # rclpy cannot be imported in this process nor in any it starts (a sitecustomize on PYTHONPATH)
    (tmp_path / "site").mkdir()
    (tmp_path / "site/sitecustomize.py").write_text("import sys\nsys.modules['rclpy'] = None\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path / "site"), ROS_DOMAIN_ID="0",
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    argv = [a.replace("BAG", str(tmp_path / "bag")) for a in argv] + (["--out", str(tmp_path / "out")]
                                                                        if argv[0] == "run" else [])
    r = run([sys.executable, "-m", "gyro_sim.apps.cli", *argv], timeout=300, cwd=tmp_path, env=env)
    assert (r.returncode, r.stderr.splitlines()) == (2, [f"error: {what} {ROS_MISSING}"]), r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site"]  # nothing was run or written
# --- parameter files under a namespace ------------------------------------------------------------

NODES_WITH_PARAMS = """
import json, sys
import rclpy
from gyro_ctl.ros.controller_node import ControllerNode
from gyro_sim.ros.simulator_node import SimulatorNode
ns, files = sys.argv[1], sys.argv[2:]
args = ["nodes", "--ros-args", *(a for f in files for a in ("--params-file", f))] + (["-r", "__ns:=" + ns] * bool(ns))
rclpy.init(args=args)
sim, ctl = SimulatorNode(), ControllerNode()
print(json.dumps({"ns": [sim.get_namespace(), ctl.get_namespace()],
                  "gyro_simulator": {k: sim.get_parameter(k).value for k in ("scene", "mode", "watchdog_timeout")},
                  "gyro_controller": {k: ctl.get_parameter(k).value for k in ("scene", "law", "control_current")}}))
sim.destroy_node(); ctl.destroy_node(); rclpy.shutdown()
"""


def params_file(node: str) -> dict:
    """The ros__parameters of ``node`` in config/<sim|ctl>.params.yaml, whatever its node-name key."""
    f = ROOT / "config" / {"gyro_simulator": "simulator.params.yaml", "gyro_controller": "controller.params.yaml"}[node]
    (key, value), = yaml.safe_load(f.read_text()).items()
    assert key.split("/")[-1] == node, key
    return value["ros__parameters"]


@pytest.mark.parametrize("ns", ["", "/sim1", "/a/b"])
def test_params_files_apply_under_a_namespace(ns):
    pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")
    from test_ros import unique_domain

    r = run([sys.executable, "-c", NODES_WITH_PARAMS, ns, ROOT / "config/simulator.params.yaml",
             ROOT / "config/controller.params.yaml"], timeout=180,
            env=dict(os.environ, ROS_DOMAIN_ID=str(unique_domain()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"))
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout.splitlines()[-1])
    assert got["ns"] == [ns or "/"] * 2
    for node in ("gyro_simulator", "gyro_controller"):
        want = params_file(node)
        assert got[node] == {k: want[k] for k in got[node]}, (node, got[node])


# --- the launch file ------------------------------------------------------------------------------

class Stub:
    """A launch or launch_ros class: keeps its arguments; equal to a stub of the same class and arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs

    def __eq__(self, other):
        return type(self) is type(other) and (self.args, self.kwargs) == (other.args, other.kwargs)

    __hash__ = None

    def __repr__(self):
        return f"{type(self).__name__}{self.args}{self.kwargs}"


def stub_module(name: str) -> types.ModuleType:
    """A module whose every attribute is a Stub subclass of that name (made once)."""
    mod = types.ModuleType(name)
    made = {}

    def getattr_(attr):
        if attr.startswith("__"):
            raise AttributeError(attr)
        return made.setdefault(attr, type(attr, (Stub,), {}))

    mod.__getattr__ = getattr_
    mod.__path__ = []  # a package: its submodules import
    return mod


@pytest.fixture
def launch_stubs(monkeypatch):
    mods = {n: stub_module(n) for n in ("launch", "launch.actions", "launch.conditions", "launch.substitutions",
                                        "launch_ros", "launch_ros.actions", "launch_ros.parameter_descriptions",
                                        "launch_ros.substitutions")}
    for n, m in mods.items():
        monkeypatch.setitem(sys.modules, n, m)
    return types.SimpleNamespace(**{n.replace(".", "_"): m for n, m in mods.items()})


def load_launch_file() -> types.ModuleType:
    """launch/gyro_sim.launch.py as a module (with the ``launch_stubs`` fixture in place of launch/launch_ros)."""
    spec = importlib.util.spec_from_file_location("gyro_sim_launch", ROOT / "launch/gyro_sim.launch.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_launch_file(launch_stubs):
    s = launch_stubs
    ld = load_launch_file().generate_launch_description()
    assert type(ld) is s.launch.LaunchDescription
    entities = list(ld.args[0])
    LC, Node = s.launch_substitutions.LaunchConfiguration, s.launch_ros_actions.Node

    args = {e.args[0]: e.kwargs["default_value"] for e in entities if type(e) is s.launch_actions.DeclareLaunchArgument}
    sim = params_file("gyro_simulator")
    share = s.launch_ros_substitutions.FindPackageShare("gyro_sim")
    sim_file = s.launch_substitutions.PathJoinSubstitution([share, "config", "simulator.params.yaml"])
    assert args == {"scene": sim["scene"], "mode": sim["mode"], "namespace": "", "use_controller": "true",
                    "record": "", "controller_params": "", "params_file": sim_file}

    # DDS on localhost unless the environment sets the range, before any node starts
    env = s.launch_actions.SetEnvironmentVariable(
        "ROS_AUTOMATIC_DISCOVERY_RANGE",
        s.launch_substitutions.EnvironmentVariable("ROS_AUTOMATIC_DISCOVERY_RANGE", default_value="LOCALHOST"))
    nodes = [e for e in entities if type(e) is Node]
    assert env in entities and entities.index(env) < entities.index(nodes[0])
    string = s.launch_ros_parameter_descriptions.ParameterValue
    scene = {"scene": string(LC("scene"), value_type=str)}

    # the simulator: its parameter file (params_file), scene, mode and record over it
    (simulator,) = nodes
    assert (simulator.kwargs["package"], simulator.kwargs["executable"], simulator.kwargs["name"]) == \
        ("gyro_sim", "simulator", "gyro_simulator")
    assert simulator.kwargs["namespace"] == LC("namespace") and "condition" not in simulator.kwargs
    assert simulator.kwargs["parameters"] == [LC("params_file"), {k: string(LC(k), value_type=str)
                                                                  for k in ("scene", "mode", "record")}]
    assert (ROOT / "config" / "simulator.params.yaml").is_file()

    # the controller (use_controller): the scene's own law unless controller_params names a file (before: always
    # config/controller.params.yaml, psi_switching: scene:=spinup_thin_shell ran the wrong law)
    (group,) = [e for e in entities if type(e) is s.launch_actions.GroupAction]
    assert group.kwargs["condition"] == s.launch_conditions.IfCondition(LC("use_controller"))
    own, given = group.kwargs["actions"]
    for n in (own, given):
        assert (n.kwargs["package"], n.kwargs["executable"], n.kwargs["name"]) == \
            ("gyro_ctl", "controller", "gyro_controller")
        assert n.kwargs["namespace"] == LC("namespace")
    IfC, subs = s.launch_conditions.IfCondition, s.launch_substitutions
    assert own.kwargs["parameters"] == [scene]
    assert own.kwargs["condition"] == IfC(subs.EqualsSubstitution(LC("controller_params"), ""))
    assert given.kwargs["parameters"] == [LC("controller_params"), scene]
    assert given.kwargs["condition"] == IfC(subs.NotEqualsSubstitution(LC("controller_params"), ""))


def test_launch_file_with_upstream_launch():
    """The launch file under the real ros2/launch and launch_ros (pure Python; skipped where they are not
    installed): scene:=spinup_thin_shell starts the controller with the scene alone (its own law, spinup), and
    controller_params:=FILE starts it with that file."""
    launch = pytest.importorskip("launch", reason="ros2/launch is not installed (a ROS 2 install has it)")
    if not hasattr(launch, "LaunchContext"):
        pytest.skip("the 'launch' module here is not ros2/launch")
    pytest.importorskip("launch_ros", reason="ros2/launch_ros is not installed (a ROS 2 install has it)")
    from launch.actions import GroupAction
    from launch_ros.actions import Node

    spec = importlib.util.spec_from_file_location("gyro_sim_launch_real", ROOT / "launch/gyro_sim.launch.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for given, which in (("", 0), (str(ROOT / "config" / "controller.params.yaml"), 1)):
        ctx = launch.LaunchContext()
        for name, default, _ in mod.ARGUMENTS:
            ctx.launch_configurations[name] = default
        ctx.launch_configurations.update(scene="spinup_thin_shell", controller_params=given)
        (group,) = [e for e in mod.generate_launch_description().entities if isinstance(e, GroupAction)]
        assert group.condition.evaluate(ctx)
        nodes = [e for e in group.get_sub_entities() if isinstance(e, Node)]  # (own law, the file's)
        assert [n.condition.evaluate(ctx) for n in nodes] == [which == 0, which == 1]


# --- colcon build ---------------------------------------------------------------------------------

def colcon_env(ws: Path) -> dict:
    """No user colcon defaults, no ament prefixes of the caller; the venv's Python first on PATH."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("AMENT_PREFIX_PATH", "COLCON_PREFIX_PATH", "PYTHONPATH", "NUMBA_CACHE_DIR")}
    # (the build compiles the default scene's kernels alone: test_colcon_first_run_compiles_nothing)
    return dict(env, COLCON_HOME=str(ws / "colcon_home"), PATH=f"{BIN}{os.pathsep}{env.get('PATH', '')}",
                GYRO_SIM_PRECOMPILE="spinup_thin_shell")


@pytest.fixture(scope="module", params=["plain", "symlink"])
def colcon_ws(request, tmp_path_factory):
    """A workspace ws/src/gyro_sim (a copy of the repo) built by the venv's colcon."""
    pytest.importorskip("colcon_ros", reason="colcon is in the 'test' extra (pip install '.[test]')")
    ws = tmp_path_factory.mktemp(f"ws_{request.param}")
    shutil.copytree(ROOT, ws / "src" / "gyro_sim", ignore=COPY_IGNORE, symlinks=True)
    cmd = [BIN / "colcon", "--log-base", ws / "log", "build", "--base-paths", ws / "src", "--build-base", ws / "build",
           "--install-base", ws / "install"] + (["--symlink-install"] if request.param == "symlink" else [])
    r = run(cmd, timeout=600, cwd=ws, env=colcon_env(ws))
    assert r.returncode == 0, f"colcon build failed:\n{r.stdout}\n{r.stderr}"
    return types.SimpleNamespace(ws=ws, mode=request.param, src=ws / "src" / "gyro_sim",
                                 prefix=ws / "install" / "gyro_sim")


def sourced(ws, *cmd, timeout=120):
    """``cmd`` in a shell that sourced the workspace's install/local_setup.sh (as a user does)."""
    script = '. "$1/local_setup.sh" && shift && exec "$@"'
    return run(["sh", "-c", script, "sh", ws.ws / "install", *cmd], timeout=timeout, cwd=ws.ws, env=colcon_env(ws.ws))


@pytest.mark.parametrize("colcon_ws", ["plain"], indirect=True)
def test_colcon_finds_gyro_sim_only(colcon_ws):
    # resource/gyro_ctl_manifest/package.xml is gyro_ctl's manifest, not a package colcon should build
    r = run([BIN / "colcon", "--log-base", os.devnull, "list", "--base-paths", colcon_ws.ws / "src"],
            env=colcon_env(colcon_ws.ws))
    assert r.returncode == 0, r.stderr
    assert [line.split()[0] for line in r.stdout.splitlines()] == ["gyro_sim"], r.stdout


def test_colcon_install_tree(colcon_ws):
    p = colcon_ws.prefix
    missing = [f for f in DATA_FILES if not (p / f).is_file()]
    assert not missing, f"not installed by colcon build ({colcon_ws.mode}): {missing}"
    assert sorted(f.name for f in (p / "share/gyro_sim/config").glob("*.yaml")) == \
        sorted(f.name for f in (ROOT / "config").glob("*.yaml"))
    assert manifest(p / "share/gyro_sim/package.xml").name == "gyro_sim"
    assert manifest(p / "share/gyro_ctl/package.xml").name == "gyro_ctl"  # `ros2 pkg xml gyro_ctl`
    if colcon_ws.mode == "symlink":
        assert (p / "share/gyro_sim/config/free_rotor.yaml").resolve() == (colcon_ws.src / "config/free_rotor.yaml")


def test_colcon_installed_package_imports(colcon_ws):
    r = sourced(colcon_ws, "python", "-c", "import json, gyro_sim, gyro_ctl.laws; "
                "print(json.dumps([gyro_sim.__file__, gyro_ctl.laws.__file__]))")
    assert r.returncode == 0, r.stderr
    files = [Path(f) for f in json.loads(r.stdout)]
    if colcon_ws.mode == "symlink":  # the build folder links the sources: edits are live
        assert all(f.resolve().is_relative_to(colcon_ws.src) for f in files), files
    else:
        site = next((colcon_ws.prefix / "lib").glob("python3*/site-packages"))
        assert all(f.is_relative_to(site) and not f.is_symlink() for f in files), files


def test_colcon_executables_run(colcon_ws):
    # `ros2 run gyro_sim gyro-sim ...`, `ros2 run gyro_sim simulator`, `ros2 run gyro_ctl controller`
    lib = colcon_ws.prefix / "lib"
    for exe, expect in ((lib / "gyro_sim/gyro-sim", "usage: gyro-sim"), (lib / "gyro_sim/simulator", "usage:"),
                        (lib / "gyro_ctl/controller", "usage:")):
        r = sourced(colcon_ws, exe, "--help")
        assert r.returncode == 0 and r.stdout.startswith(expect), (exe, r.stdout, r.stderr)


def test_colcon_first_run_compiles_nothing(colcon_ws):
    """colcon build compiles the kernels into what it installs (plain: the install tree; --symlink-install: next to
    the sources the build links): the first run of the scene in the sourced workspace compiles nothing."""
    from test_install import FIRST_RUN

    r = sourced(colcon_ws, "python", "-c", FIRST_RUN, timeout=300)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.splitlines()[-1])
    print(f"\n  colcon ({colcon_ws.mode}): first run {out['compile_s']:.2f} s compiling, {out['steps']} steps")
    assert out["compile_s"] == 0.0 and out["steps"] > 0


# --- the manifests ----------------------------------------------------------------------------------

#: top-level module imported by the code → rosdep key (None: no key in rosdistro; the manifest says so)
MODULE_KEYS = {
    "rclpy": "rclpy", "rcl_interfaces": "rcl_interfaces", "ament_index_python": "ament_index_python",
    "std_msgs": "std_msgs", "geometry_msgs": "geometry_msgs", "sensor_msgs": "sensor_msgs",
    "rosgraph_msgs": "rosgraph_msgs", "builtin_interfaces": "builtin_interfaces",
    "diagnostic_msgs": "diagnostic_msgs", "std_srvs": "std_srvs", "tf2_msgs": "tf2_msgs",
    "numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml", "numba": "python3-numba",
    "pydantic": "python3-pydantic", "matplotlib": "python3-matplotlib", "rosbags": "python3-rosbags-pip",
    "mcap": None, "tqdm": "python3-tqdm", "dask": None, "distributed": None, "pyarrow": None,
    "pandas": "python3-pandas", "xarray": None,
    "foxglove": None,  # foxglove-sdk (the extra 'live')
    "websockets": "python3-websockets",  # the live view's relay (the extra 'live': gyro_sim/io/live_relay.py)
    "gyro_sim": "gyro_sim", "launch": "launch", "launch_ros": "launch_ros",
    "pdoc": None,  # the 'docs' extra (gyro_sim/apps/api_docs.py)
}
#: pip requirement of setup.py → rosdep key (ros-* wheels: the ROS package of that name)
PIP_KEYS = {
    "numpy": "python3-numpy", "scipy": "python3-scipy", "pyyaml": "python3-yaml", "numba": "python3-numba",
    "pydantic": "python3-pydantic", "matplotlib": "python3-matplotlib", "rosbags": "python3-rosbags-pip",
    "mcap": None, "pytest": "python3-pytest", "hypothesis": "python3-hypothesis", "mpmath": None,
    "mcap-ros2-support": "mcap-ros2-support", "dask": None, "pyarrow": None, "tqdm": "python3-tqdm",
    "pandas": "python3-pandas", "xarray": None,
    "websockets": "python3-websockets", "foxglove-sdk": None,
    "ruff": None, "mypy": "python3-mypy",
    # (.ci/run's workers; `colcon test` runs the suite in one process, without it)
    "pytest-xdist": None,
}
#: ros-* wheels that are not dependencies of the package: the middleware is the user's choice
#: (RMW_IMPLEMENTATION; rclpy depends on rmw_implementation), the wheels need one installed
NOT_A_DEPENDENCY = {"rmw_fastrtps_cpp"}


def imported_modules(folder: str) -> set:
    """Third-party top-level modules imported anywhere in ``folder`` of the repo (stdlib and this
    distribution's gyro_sim, gyro_ctl excluded)."""
    out = set()
    for path in (ROOT / folder).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                out |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                out.add(node.module.split(".")[0])
    return out - set(sys.stdlib_module_names) - {"gyro_sim", "gyro_ctl", "__future__"}


def message_packages() -> set:
    """Packages of the message types the nodes load by name (``gyro_sim.io.messages.TOPICS``)."""
    from gyro_sim.io.messages import TOPICS

    return {t.split("/")[0] for t in TOPICS.values()}


def says_no_key(xml: Path, pip: str) -> bool:
    """A comment of the manifest names the pip package ``pip`` and says it has no rosdep key."""
    comments = re.findall(r"<!--(.*?)-->", xml.read_text(encoding="utf-8"), re.S)
    return any(re.search(rf"(?<![\w-]){re.escape(pip)}(?![\w-])", c) and "no rosdep key" in c for c in comments)


def check_declared(xml: Path, modules, deps: set) -> list:
    """The modules whose key ``deps`` lacks (or, without a key, that no comment of ``xml`` names)."""
    bad = []
    for m in sorted(modules):
        assert m in MODULE_KEYS, f"{m}: imported by the code; add its rosdep key to {xml.name} and MODULE_KEYS"
        key = MODULE_KEYS[m]
        if (key is None and not says_no_key(xml, {"distributed": "dask"}.get(m, m))) \
                or (key is not None and key not in deps):
            bad.append((m, key))
    return bad


def test_manifest_declares_every_import():
    pkg = manifest(ROOT / "package.xml")
    pkg.validate()
    modules = imported_modules("gyro_sim") | imported_modules("gyro_ctl") | imported_modules("launch")
    # pytest: imported only by gyro_sim/apps/testing.py, the pytest plugin (entry point pytest11), which runs inside
    # pytest alone: a test dependency of the package, not a run dependency
    plugin = ROOT / "gyro_sim" / "apps" / "testing.py"
    for path in (ROOT / "gyro_sim").rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        imports = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        assert path == plugin or "pytest" not in imports, f"{path.name} imports pytest"
    assert "python3-pytest" in names(pkg.test_depends)
    modules -= {"pytest"}
    assert not check_declared(ROOT / "package.xml", modules | message_packages(), names(pkg.exec_depends))


def pyproject() -> dict:
    """pyproject.toml, parsed."""
    try:
        import tomllib
    except ImportError:  # Python 3.10 (the 'test' extra brings tomli there)
        import tomli as tomllib
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def setup_requirements() -> dict:
    """The package's dependencies and extras (pyproject.toml): {'': [...], extra: [...]}."""
    project = pyproject()["project"]
    return {"": project["dependencies"], **project["optional-dependencies"]}


def rosdep_key(requirement: str):
    name = Requirement(requirement).name.lower()
    if name.startswith("ros-"):
        return name[4:].replace("-", "_")
    assert name in PIP_KEYS, f"{name}: a requirement of pyproject.toml; add its rosdep key to package.xml and PIP_KEYS"
    return PIP_KEYS[name]


def test_manifest_declares_setup_requirements():
    pkg = manifest(ROOT / "package.xml")
    req = setup_requirements()
    run_deps, test_deps = names(pkg.exec_depends), names(pkg.test_depends)
    for extra, deps in (("", run_deps), ("ros", run_deps), ("sweep", run_deps), ("data", run_deps),
                        ("live", run_deps), ("test", test_deps)):
        for r in req[extra]:
            if extra == "test" and (Requirement(r).name.startswith("colcon-") or Requirement(r).name == "tomli"):
                continue  # the build tool; the TOML reader of Python < 3.11 (tomllib of a ROS distribution's)
            key = rosdep_key(r)
            if key in NOT_A_DEPENDENCY:
                continue
            if key is None:
                assert says_no_key(ROOT / "package.xml", Requirement(r).name), f"{r}: no rosdep key, not said"
            else:
                assert key in deps, f"pyproject.toml {extra or 'dependencies'} {r!r}: {key} not in package.xml"


def test_gyro_ctl_manifest():
    ctl, sim = manifest(ROOT / "resource/gyro_ctl_manifest/package.xml"), manifest(ROOT / "package.xml")
    ctl.validate()
    import gyro_sim

    assert (ctl.name, sim.name) == ("gyro_ctl", "gyro_sim")
    assert ctl.version == sim.version == gyro_sim.__version__ == distribution("gyro_sim").version
    modules = imported_modules("gyro_ctl") | {"gyro_sim", "sensor_msgs", "geometry_msgs"}  # its topics' types
    assert not check_declared(ROOT / "resource/gyro_ctl_manifest/package.xml", modules, names(ctl.exec_depends))


# --- the ament index of an editable install (gyro-sim ros-index) -------------------------------------

def ament(prefix: Path, code: str, **kw):
    env = {k: v for k, v in os.environ.items() if k != "AMENT_PREFIX_PATH"}
    return run([sys.executable, "-c", code], env=dict(env, AMENT_PREFIX_PATH=str(prefix)), **kw)


def check_ament_prefix(prefix: Path):
    """``ros2 run``'s lookups resolve gyro_sim and gyro_ctl to ``prefix``; the executables answer --help."""
    r = ament(prefix, "import json; from ament_index_python.packages import get_package_prefix as p, "
                      "get_package_share_directory as s; "
                      "print(json.dumps([p('gyro_sim'), p('gyro_ctl'), s('gyro_sim'), s('gyro_ctl')]))")
    assert r.returncode == 0, r.stderr
    assert [Path(x) for x in json.loads(r.stdout)] == [prefix, prefix, prefix / "share/gyro_sim",
                                                       prefix / "share/gyro_ctl"]
    assert manifest(prefix / "share/gyro_ctl/package.xml").name == "gyro_ctl"
    for exe in ("lib/gyro_sim/simulator", "lib/gyro_ctl/controller"):
        # whatever PATH says: the executables name their interpreter
        r = run([prefix / exe, "--help"], timeout=60, env=dict(os.environ, PATH="/usr/bin:/bin"))
        assert r.returncode == 0 and r.stdout.startswith("usage:"), (exe, r.stdout, r.stderr)


def test_ros_index_cli(tmp_path):
    prefix = tmp_path / "prefix"
    r = run([sys.executable, "-m", "gyro_sim.apps.cli", "ros-index", prefix])
    assert r.returncode == 0, r.stderr
    tree = sorted(p.relative_to(prefix) for p in prefix.rglob("*"))
    assert run([sys.executable, "-m", "gyro_sim.apps.cli", "ros-index", prefix]).returncode == 0  # idempotent
    assert sorted(p.relative_to(prefix) for p in prefix.rglob("*")) == tree
    assert all((prefix / f).is_file() for f in DATA_FILES)
    check_ament_prefix(prefix)


@pytest.mark.parametrize("colcon_ws", ["plain"], indirect=True)
def test_ros_index_is_what_colcon_installs(colcon_ws, tmp_path):
    """The same files as setup.py's data_files (colcon's install less its own files and the console scripts)."""
    from gyro_sim.ros.index import install_index

    p = colcon_ws.prefix
    scripts = {f"lib/gyro_sim/{e.name}" for e in distribution("gyro_sim").entry_points if e.group == "console_scripts"}
    colcon_own = re.compile(r"lib/python3[^/]*/|share/colcon-core/"
                            r"|share/gyro_sim/(hook/|package\.(dsv|sh|bash|zsh|ps1)$)")
    installed = {f.relative_to(p).as_posix() for f in p.rglob("*") if f.is_file()}
    data_files = {f for f in installed if not colcon_own.match(f)} - scripts
    install_index(tmp_path, colcon_ws.src)
    assert {f.relative_to(tmp_path).as_posix() for f in tmp_path.rglob("*") if f.is_file()} == data_files


def test_ros_index_removes_stale_links(tmp_path):
    from gyro_sim.ros.index import install_index

    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=COPY_IGNORE, symlinks=True)
    install_index(tmp_path / "prefix", src)
    old = tmp_path / "prefix/share/gyro_sim/config/free_rotor.yaml"
    assert old.resolve() == src / "config/free_rotor.yaml"
    (src / "config/free_rotor.yaml").unlink()
    assert old in install_index(tmp_path / "prefix", src)
    assert not old.is_symlink() and (tmp_path / "prefix/share/gyro_sim/config/three_stators.yaml").is_file()


def test_setup_venv_has_the_ament_index():
    """.ci/setup lays the index out in .venv: AMENT_PREFIX_PATH=$PWD/.venv ros2 run gyro_sim simulator."""
    prefix = Path(sys.prefix)
    if not (prefix / ".setup-stamp").is_file():
        pytest.skip("not the .venv made by .ci/setup")
    check_ament_prefix(prefix)
