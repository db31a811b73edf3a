"""mcl config from-amcl: ROS AMCL parameters (nav2 params YAML, ROS 1 amcl YAML, ROS 1 .launch) as an mcl config."""

from __future__ import annotations

import math

import pytest
import yaml

from mcl.amcl_params import convert
from mcl.cli import main
from mcl.config import load_config
from mcl.errors import MclError

# nav2_bringup/params/nav2_params.yaml's amcl block (Humble on), with a start pose, among other nodes
NAV2 = """\
amcl:
  ros__parameters:
    use_sim_time: True
    alpha1: 0.2
    alpha2: 0.2
    alpha3: 0.2
    alpha4: 0.2
    alpha5: 0.2
    base_frame_id: "base_footprint"
    beam_skip_distance: 0.5
    beam_skip_error_threshold: 0.9
    beam_skip_threshold: 0.3
    do_beamskip: false
    global_frame_id: "map"
    lambda_short: 0.1
    laser_likelihood_max_dist: 2.0
    laser_max_range: 100.0
    laser_min_range: -1.0
    laser_model_type: "likelihood_field"
    max_beams: 60
    max_particles: 2000
    min_particles: 500
    odom_frame_id: "odom"
    pf_err: 0.05
    pf_z: 0.99
    recovery_alpha_fast: 0.0
    recovery_alpha_slow: 0.0
    resample_interval: 1
    robot_model_type: "nav2_amcl::DifferentialMotionModel"
    save_pose_rate: 0.5
    sigma_hit: 0.2
    tf_broadcast: true
    transform_tolerance: 1.0
    update_min_a: 0.2
    update_min_d: 0.25
    z_hit: 0.5
    z_max: 0.05
    z_rand: 0.5
    z_short: 0.05
    scan_topic: scan
    set_initial_pose: true
    initial_pose:
      x: 1.5
      y: -2.0
      z: 0.0
      yaw: 0.3

bt_navigator:
  ros__parameters:
    use_sim_time: True
    global_frame: map
    robot_base_frame: base_link
    transform_tolerance: 0.1

controller_server:
  ros__parameters:
    controller_frequency: 20.0
    FollowPath:
      plugin: "dwb_core::DWBLocalPlanner"
      max_vel_x: 0.26
"""

ROS1 = """\
amcl:
  odom_model_type: diff-corrected
  odom_alpha1: 0.005
  odom_alpha2: 0.005
  odom_alpha3: 0.01
  odom_alpha4: 0.005
  laser_model_type: likelihood_field_prob
  do_beamskip: true
  beam_skip_distance: 0.4
  beam_skip_threshold: 0.3
  beam_skip_error_threshold: 0.85
  laser_z_hit: 0.9
  laser_z_rand: 0.1
  laser_sigma_hit: 0.1
  laser_max_beams: 120
  laser_max_range: 12.0
  min_particles: 500
  max_particles: 5000
  kld_err: 0.05
  kld_z: 2.326
  recovery_alpha_slow: 0.001
  recovery_alpha_fast: 0.1
  initial_pose_x: 2.0
  initial_pose_y: 3.0
  initial_pose_a: 1.57
  initial_cov_xx: 0.04
  initial_cov_yy: 0.09
  initial_cov_aa: 0.01
  base_frame_id: /base_link
  transform_tolerance: 0.2
"""

LAUNCH = """\
<launch>
  <arg name="scan_topic" default="base_scan"/>
  <arg name="initial_pose_x" default="0.5"/>
  <node pkg="amcl" type="amcl" name="amcl" output="screen">
    <remap from="scan" to="$(arg scan_topic)"/>
    <param name="odom_model_type" value="diff"/>
    <param name="odom_alpha1" value="0.2"/>
    <param name="odom_alpha2" value="0.2"/>
    <param name="odom_alpha3" value="0.8"/>
    <param name="odom_alpha4" value="0.2"/>
    <param name="laser_max_beams" value="30"/>
    <param name="min_particles" value="500"/>
    <param name="max_particles" value="5000"/>
    <param name="laser_model_type" value="likelihood_field"/>
    <param name="update_min_d" value="0.2"/>
    <param name="initial_pose_x" value="$(arg initial_pose_x)"/>
    <param name="base_frame_id" value="$(env ROBOT_BASE)"/>
    <rosparam>
      initial_cov_xx: 0.01
    </rosparam>
  </node>
</launch>
"""


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_a_nav2_params_file_converts_to_the_keys_its_amcl_block_means(tmp_path):
    p = _write(tmp_path, "nav2_params.yaml", NAV2)
    r = convert(p)
    k = r.keys
    assert r.warnings == []  # use_sim_time is every ROS 2 node's; the other nodes' blocks are not read
    assert k["filter.particles"] == 2000 and k["filter.min_particles"] == 500 and k["filter.kld"] is True
    assert k["filter.kld_epsilon"] == 0.05
    assert round(k["filter.kld_delta"], 3) == 0.161  # pf_z is the quantile z itself: delta = 1 - Phi(0.99)
    assert (k["filter.update_min_d"], k["filter.update_min_a"]) == (0.25, 0.2)
    assert k["filter.initial_pose"] == [1.5, -2.0, 0.3]  # set_initial_pose: true
    assert "filter.initial_std" not in k  # nav2 has no initial covariance parameter
    assert "filter.recovery" not in k  # both recovery rates 0: mcl's own default recovery is left
    assert (k["motion.model"], k["motion.noise_form"], k["motion.noise_step"]) == ("odometry", "variance", 0.0)
    assert [k[f"motion.alpha{i}"] for i in range(1, 5)] == [0.2] * 4
    assert "motion.alpha5" not in k  # omni only; mcl's alpha5 is the velocity model's
    assert k["sensor.model"] == "likelihood_field" and k["sensor.likelihood_field.interior"] == "zero"
    zh, zr = k["sensor.likelihood_field.z_hit"], k["sensor.likelihood_field.z_rand"]
    # AMCL's unnormalised Gaussian made a density: the same p(z) up to a common factor
    assert zh + zr == pytest.approx(1.0, abs=1e-5)
    assert zh / zr == pytest.approx(0.5 * math.sqrt(2 * math.pi) * 0.2 / 0.5, rel=1e-5)
    assert k["sensor.likelihood_field.sigma_hit"] == 0.2 and k["sensor.likelihood_field.likelihood_max_dist"] == 2.0
    assert k["sensor.max_beams"] == 60 and k["sensor.range_max"] == 100.0 and "sensor.range_min" not in k
    assert "sensor.beam_skip" not in k  # do_beamskip matters with likelihood_field_prob only
    assert k["topics.scan"] == "/scan"
    assert (k["frames.odom"], k["frames.base"]) == ("odom", "base_footprint")
    # the text: each key commented with its AMCL parameter; every parameter of the block accounted for
    lines = r.text.splitlines()
    assert any(ln.strip().startswith("kld_delta: 0.1611") and "pf_z 0.99" in ln for ln in lines)
    assert any(ln.strip().startswith("particles: 2000") and "max_particles 2000" in ln for ln in lines)
    for name in yaml.safe_load(NAV2)["amcl"]["ros__parameters"]:
        assert name in r.text, name
    assert "Not used (no mcl counterpart):" in r.text and "transform_tolerance 1" in r.text
    # the text is the keys, as load_config reads them
    out = _write(tmp_path, "out.yaml", r.text)
    cfg = load_config(out)
    assert cfg.filter.kld_delta == k["filter.kld_delta"] and cfg.sensor.likelihood_field.interior == "zero"
    assert cfg.frames.base == "base_footprint" and cfg.topics.scan == "/scan"
    assert cfg.quality.lost_below == load_config(None).quality.lost_below  # the rest are default.yaml's


def test_a_bare_ros_parameters_mapping_and_a_flat_mapping_read_alike(tmp_path):
    block = yaml.safe_load(NAV2)["amcl"]
    bare = convert(_write(tmp_path, "bare.yaml", yaml.safe_dump(block))).keys
    flat = convert(_write(tmp_path, "flat.yaml", yaml.safe_dump(block["ros__parameters"]))).keys
    assert bare == flat == convert(_write(tmp_path, "full.yaml", NAV2)).keys


def test_ros1_likelihood_field_prob_is_beam_skipping_the_amcl_way(tmp_path):
    r = convert(_write(tmp_path, "amcl.yaml", ROS1))
    k = r.keys
    assert r.warnings == []  # diff-corrected is mcl's variance form: nothing to warn about
    assert k["sensor.model"] == "likelihood_field" and k["sensor.likelihood_field.interior"] == "zero"
    assert k["sensor.beam_skip"] is True and k["sensor.beam_skip_rule"] == "amcl"
    assert (k["sensor.beam_skip_distance"], k["sensor.beam_skip_threshold"],
            k["sensor.beam_skip_error_threshold"]) == (0.4, 0.3, 0.85)
    assert k["sensor.max_beams"] == 120 and k["sensor.range_max"] == 12.0
    assert [k[f"motion.alpha{i}"] for i in range(1, 5)] == [0.005, 0.005, 0.01, 0.005]
    assert round(k["filter.kld_delta"], 4) == 0.01  # kld_z 2.326 is the book's delta = 0.01
    assert k["filter.recovery"] == "augmented"
    assert (k["filter.recovery_alpha_slow"], k["filter.recovery_alpha_fast"]) == (0.001, 0.1)
    assert k["filter.initial_pose"] == [2.0, 3.0, 1.57]
    assert k["filter.initial_std"] == pytest.approx([0.2, 0.3, 0.1])  # square roots of the covariances
    assert k["frames.base"] == "base_link"


def test_likelihood_field_prob_without_do_beamskip_skips_nothing_as_in_amcl(tmp_path):
    # amcl_laser.cpp / likelihood_field_model_prob.cpp skip beams only when do_beamskip is true (default false)
    text = ROS1.replace("  do_beamskip: true\n", "")
    k = convert(_write(tmp_path, "amcl.yaml", text)).keys
    assert k["sensor.beam_skip"] is False and k["sensor.beam_skip_rule"] == "amcl"


def test_a_launch_file_with_args_remaps_and_a_rosparam_block(tmp_path):
    r = convert(_write(tmp_path, "amcl_diff.launch", LAUNCH))
    k = r.keys
    assert k["topics.scan"] == "/base_scan"  # <remap from="scan" to="$(arg scan_topic)"/>
    assert k["filter.initial_pose"] == [0.5, 0.0, 0.0]  # $(arg initial_pose_x); y and a AMCL's 0
    assert k["filter.initial_std"] == pytest.approx([0.1, 0.5, math.pi / 12])  # <rosparam>; AMCL's defaults
    assert [k[f"motion.alpha{i}"] for i in range(1, 5)] == [0.2, 0.2, 0.8, 0.2]
    assert k["sensor.max_beams"] == 30 and k["filter.particles"] == 5000
    assert "frames.base" not in k  # $(env ...) cannot be resolved
    assert len(r.warnings) == 2
    env, diff = r.warnings
    assert "base_frame_id: $(env ROBOT_BASE) cannot be resolved here: not used" in env
    # ROS 1's uncorrected diff model takes the alpha expression as the std: mapped unchanged, and said so
    assert "odom_model_type diff: ROS 1's uncorrected model takes alpha1 rot^2 + alpha2 trans^2 as the std" in diff
    assert "5.6 times AMCL's" in diff  # 1 / (sqrt(0.8) * 0.2)


@pytest.mark.parametrize("model", ["omni-corrected", "omni"])
def test_omni_models_are_mcl_omni_model_with_alpha5_the_strafe_noise(tmp_path, model):
    # before mcl had an omni model: a warning, motion.model odometry and alpha5 left out
    text = ROS1.replace("diff-corrected", model) + "  odom_alpha5: 0.1\n"
    r = convert(_write(tmp_path, "amcl.yaml", text))
    assert r.keys["motion.model"] == "omni"
    assert r.keys["motion.alpha3"] == 0.01 and r.keys["motion.alpha_strafe"] == 0.1 and "motion.alpha5" not in r.keys
    assert "odom_alpha5 0.1: strafe noise from translation" in r.text
    # ROS 1's uncorrected omni alone is warned of (diff's std-for-variance bug)
    assert len(r.warnings) == (1 if model == "omni" else 0)


def test_beam_model_weights_are_made_to_sum_to_one(tmp_path):
    # nav2's defaults sum to 1.1, which mcl's beam model refuses as they are
    text = NAV2.replace('laser_model_type: "likelihood_field"', 'laser_model_type: "beam"')
    k = convert(_write(tmp_path, "beam.yaml", text)).keys
    w = [k[f"sensor.beam.{z}"] for z in ("z_hit", "z_short", "z_max", "z_rand")]
    assert sum(w) == pytest.approx(1.0, abs=1e-5)
    assert w[1] == pytest.approx(w[2]) and w[3] / w[1] == pytest.approx(10.0)  # z_rand : z_short kept
    assert k["sensor.model"] == "beam" and "sensor.likelihood_field.interior" not in k


def _one_error(capsys) -> str:
    captured = capsys.readouterr()
    err = captured.err.splitlines()
    lines = [ln for ln in err if ln.startswith("mcl: error:")]
    assert len(lines) == 1 and len(err) == 1 and not captured.out, captured
    return lines[0]


@pytest.mark.parametrize("text,msg", [
    ("laser_z_hit: -1\nlaser_z_rand: 0.05\n",
     "laser_z_hit -1: sensor.likelihood_field.z_hit: -1.0 is out of range (must be >= 0.0)"),
    ("amcl:\n  ros__parameters:\n    z_hit: abc\n", "z_hit: expected a number, got 'abc'"),
    ("max_particles: lots\n", "max_particles: expected an integer, got 'lots'"),
    ("kld_z: 40\n", "kld_z 40: filter.kld_delta: 0.0 is out of range (must be > 0.0)"),
    ("kld_err: 0\n", "kld_err 0: filter.kld_epsilon: 0.0 is out of range (must be > 0.0)"),
    ("recovery_alpha_slow: 0.2\nrecovery_alpha_fast: 0.1\n",
     "recovery_alpha_slow 0.2: filter.recovery_alpha_slow: 0.2 must be below filter.recovery_alpha_fast (0.1)"),
    ("max_beams: 3\n", "max_beams 3: quality.min_beams: 5 is more than sensor.max_beams (3): no update would have "
     "beams enough to judge"),
    ("initial_pose_x: 1\ninitial_cov_xx: -0.5\n", "initial_cov_xx: -0.5 is a variance, it must be >= 0"),
])
def test_a_value_mcl_refuses_is_one_error_naming_the_amcl_parameter(tmp_path, capsys, text, msg):
    p = _write(tmp_path, "amcl.yaml", text)
    out = tmp_path / "out.yaml"
    assert main(["config", "from-amcl", str(p), "-o", str(out)]) == 2
    assert _one_error(capsys) == f"mcl: error: {p}: {msg}"
    assert not out.exists()


def test_unknown_and_other_flavour_names_are_warnings(tmp_path, capsys):
    p = _write(tmp_path, "amcl.yaml", ROS1 + "  odom_alpha6: 0.1\n  pf_z: 0.5\n  laser_sigma_hitt: 0.3\n")
    assert main(["config", "from-amcl", str(p)]) == 0
    captured = capsys.readouterr()
    err = captured.err.splitlines()
    assert err == [
        f"mcl: warning: {p}: odom_alpha6: not a ROS 1 amcl parameter (did you mean odom_alpha5?): not used",
        f"mcl: warning: {p}: pf_z: a nav2_amcl parameter, not a ROS 1 amcl one (ROS 1 amcl reads kld_z): not used",
        f"mcl: warning: {p}: laser_sigma_hitt: not a ROS 1 amcl parameter (did you mean laser_sigma_hit?): not used",
    ]
    assert yaml.safe_load(captured.out)["filter"]["kld_delta"] == pytest.approx(0.01, abs=1e-4)  # kld_z, not pf_z


@pytest.mark.parametrize("name,content,msg", [
    ("other.yaml", "foo: 1\nbar: {baz: 2}\n", "no AMCL parameters found"),
    ("costmap.yaml", "local_costmap:\n  ros__parameters:\n    transform_tolerance: 0.3\n    robot_base_frame: base\n",
     "no AMCL parameters found"),
    ("empty.yaml", "", "no AMCL parameters found"),
    ("list.yaml", "- 1\n- 2\n", "no AMCL parameters found"),
    ("bad.yaml", "a: [1, 2\n", ":2: invalid YAML"),
    ("bad.launch", '<launch><node pkg="amcl" type="amcl">\n</launch>', ":2: invalid XML"),
    ("other.launch", '<launch><node pkg="map_server" type="map_server"/></launch>', 'no <node pkg="amcl">'),
    ("blob.bin", b"\x89PNG\r\n\x1a\n\xff\xfe\x00", "not a text file"),
    ("mcl.yaml", "filter:\n  particles: 100\n  update_min_d: 0.1\n", "an mcl config"),
])
def test_a_file_that_holds_no_amcl_parameters_is_one_error_naming_it(tmp_path, capsys, name, content, msg):
    p = tmp_path / name
    p.write_bytes(content if isinstance(content, bytes) else content.encode())
    assert main(["config", "from-amcl", str(p)]) == 2
    line = _one_error(capsys)
    assert line.startswith(f"mcl: error: {p}") and msg in line


def test_the_converted_config_runs(tmp_path, capsys):
    from mcl.simulate import simulate

    world = tmp_path / "world"
    simulate(world, seed=3, duration=10)
    text = NAV2.replace("    set_initial_pose: true\n", "")  # nav2 then waits for /initialpose: a global start
    p = _write(tmp_path, "nav2_params.yaml", text)
    out = tmp_path / "amcl.yaml"
    assert main(["config", "from-amcl", str(p), "-o", str(out)]) == 0
    assert "filter.initial_pose" not in convert(p).keys
    run = tmp_path / "run"
    assert main(["run", str(out), "--map", str(world / "map.yaml"), "--log", str(world / "log.clf"),
                 "--truth", str(world / "truth.tum"), "--rerun", "off", "--no-progress", "--threads", "1",
                 "--out", str(run)]) == 0
    used = load_config(run / "config.yaml")
    assert used.filter.particles == 2000 and used.sensor.likelihood_field.interior == "zero"
    assert (run / "trajectory.tum").stat().st_size > 0
    assert "mcl: error" not in capsys.readouterr().err


# --- real files (audit): trimmed copies of public robot repositories' AMCL parameters

# pal-robotics/tiago_navigation tiago_2dnav/config/localization/amcl.yaml: laser_lambda_short twice
TIAGO = """\
odom_model_type: diff
odom_alpha1    : 0.2
odom_alpha2    : 0.2
odom_alpha3    : 0.8
odom_alpha4    : 0.2
min_particles    : 500
max_particles    : 5000
laser_model_type         : likelihood_field
laser_z_hit              : 0.5
laser_z_rand             : 0.5
laser_sigma_hit          : 0.2
laser_lambda_short       : 0.1
laser_lambda_short       : 0.1
laser_likelihood_max_dist: 2.0
base_frame_id: base_footprint
"""


def test_a_parameter_given_twice_is_read_as_rosparam_reads_it(tmp_path):
    r = convert(_write(tmp_path, "amcl.yaml", TIAGO))  # mcl's own files refuse a duplicate key; rosparam keeps the last
    assert any("line 13: laser_lambda_short given twice: the last is read" in w for w in r.warnings)
    assert r.keys["filter.particles"] == 5000 and r.keys["frames.base"] == "base_footprint"


# ros-planning/navigation amcl/examples/amcl_omni.launch (trimmed)
OMNI_LAUNCH = """\
<launch>
<node pkg="amcl" type="amcl" name="amcl">
  <param name="odom_model_type" value="omni"/>
  <param name="odom_alpha5" value="0.1"/>
  <param name="min_particles" value="500"/>
  <param name="max_particles" value="5000"/>
  <param name="odom_alpha1" value="0.2"/>
  <param name="odom_alpha2" value="0.2"/>
  <param name="odom_alpha3" value="0.8"/>
  <param name="odom_alpha4" value="0.2"/>
  <param name="update_min_d" value="0.2"/>
</node>
</launch>
"""


@pytest.mark.parametrize("model", ["omni", "omni-corrected"])
def test_omni_alphas_go_by_their_roles(tmp_path, model):
    # amcl_odom.cpp's omni: trans std from alpha3 trans^2 + alpha1 rot^2, rot std from alpha4 rot^2 + alpha2 trans^2
    text = OMNI_LAUNCH.replace('value="omni"', f'value="{model}"').replace(
        'odom_alpha1" value="0.2', 'odom_alpha1" value="0.3')
    r = convert(_write(tmp_path, "amcl_omni.launch", text))
    assert r.keys["motion.alpha1"] == 0.2 and r.keys["motion.alpha4"] == 0.3  # swapped
    assert r.keys["motion.alpha2"] == 0.2 and r.keys["motion.alpha3"] == 0.8
    assert "odom_alpha4 0.2: rotation noise from rotation" in r.text
    # ROS 1's uncorrected omni has diff's bug: the alpha expression is the std
    assert [("uncorrected omni takes alpha3 trans^2 + alpha1 rot^2 itself as the std" in w) for w in r.warnings] == (
        [True] if model == "omni" else [])


# ZebraDevs/fetch_ros fetch_navigation/launch/include/amcl.launch.xml and config/amcl.yaml (trimmed)
FETCH_LAUNCH = """\
<launch>
  <arg name="scan_topic"     default="base_scan" />
  <arg name="use_map_topic"  default="false" />
  <node pkg="amcl" type="amcl" name="amcl">
    <remap from="scan" to="$(arg scan_topic)" />
    <param name="use_map_topic"  value="$(arg use_map_topic)" />
    <rosparam file="$(find fetch_navigation)/config/amcl.yaml" command="load" />
  </node>
</launch>
"""
FETCH_YAML = """\
min_particles: 500
max_particles: 2000
kld_err: 0.01
kld_z: 0.99
laser_model_type: "likelihood_field"
odom_model_type: "diff"
odom_alpha1: 1.5
"""


def test_find_is_the_launch_files_package_folder(tmp_path):
    pkg = tmp_path / "fetch_navigation"
    (pkg / "config").mkdir(parents=True)
    (pkg / "config" / "amcl.yaml").write_text(FETCH_YAML)
    (pkg / "launch" / "include").mkdir(parents=True)
    launch = pkg / "launch" / "include" / "amcl.launch.xml"
    launch.write_text(FETCH_LAUNCH)
    k = convert(launch).keys
    assert k["filter.kld_epsilon"] == 0.01 and k["motion.alpha1"] == 1.5 and k["topics.scan"] == "/base_scan"
    # elsewhere the package cannot be found: the error says which file to give
    other = _write(tmp_path, "amcl.launch.xml", FETCH_LAUNCH)
    with pytest.raises(MclError, match=r"no AMCL parameters found .*\$\(find fetch_navigation\) cannot be resolved"):
        convert(other)


def test_a_nav2_file_without_an_amcl_node_is_refused_not_read_from_another_localizer(tmp_path, capsys):
    # navigation2's nav2_params.yaml of a release without AMCL held a localization_server whose z_hit, sigma_hit and
    # laser_max_range made it "AMCL's": exit 0, five keys and sixteen warnings
    p = tmp_path / "nav2_params.yaml"
    p.write_text(yaml.safe_dump({
        "localization_server": {"ros__parameters": {"z_hit": 0.5, "sigma_hit": 0.2, "laser_max_range": 100.0,
                                                    "base_frame_id": "base_footprint", "scan_topic": "scan"}},
        "controller_server": {"ros__parameters": {"controller_frequency": 20.0}}}))
    assert main(["config", "from-amcl", str(p)]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "no AMCL parameters found: no amcl node among its nodes (" in err[0], err
    assert "localization_server" in err[0] and "controller_server" in err[0]


def test_a_launch_files_if_and_unless_decide_which_params_are_loaded(tmp_path):
    # TIAGo's localization launch loads a second set of parameters only if="$(arg multiple)" (false by default):
    # every <param> was read whatever its condition
    p = tmp_path / "amcl.launch"
    p.write_text("""<launch>
  <arg name="multiple" default="false"/>
  <node pkg="amcl" type="amcl" name="amcl">
    <param name="odom_model_type" value="diff-corrected"/>
    <param name="max_particles" value="3000"/>
    <param name="max_particles" value="9000" if="$(arg multiple)"/>
    <param name="min_particles" value="700" unless="$(arg multiple)"/>
    <param name="min_particles" value="100" if="true"/>
    <param name="update_min_d" value="0.3" unless="1"/>
  </node>
</launch>
""")
    cfg = convert(p).keys
    assert cfg["filter.particles"] == 3000 and cfg["filter.min_particles"] == 100
    assert "filter.update_min_d" not in cfg or cfg["filter.update_min_d"] != 0.3


SIM_OR_REAL = """<launch>
  <arg name="sim" default="false"/>
  <group if="$(arg sim)">
    <arg name="particles" default="500"/>
    <node pkg="amcl" type="amcl" name="amcl_sim">
      <param name="odom_model_type" value="diff-corrected"/>
      <param name="max_particles" value="$(arg particles)"/>
      <param name="update_min_d" value="0.1"/>
    </node>
  </group>
  <group unless="$(arg sim)">
    <arg name="particles" default="4000"/>
    <node pkg="amcl" type="amcl" name="amcl_real">
      <param name="odom_model_type" value="diff-corrected"/>
      <param name="max_particles" value="$(arg particles)"/>
    </node>
  </group>
</launch>
"""


def test_an_amcl_node_in_a_group_whose_condition_is_false_is_not_the_one_read(tmp_path):
    # A launch file with a simulation and a real robot's amcl, in <group if="$(arg sim)"> / <group unless=...>:
    # the groups' conditions were not evaluated, so the first node (sim, never launched with sim false) was read
    from mcl.amcl_params import read_source

    p = _write(tmp_path, "amcl.launch", SIM_OR_REAL)
    src = read_source(p)
    assert src.where == '<node name="amcl_real">' and src.params["max_particles"] == 4000, (src.where, src.params)
    assert "update_min_d" not in src.params and not src.warnings, src.warnings
    assert convert(p).keys["filter.particles"] == 4000
    sim = _write(tmp_path, "sim.launch", SIM_OR_REAL.replace('name="sim" default="false"', 'name="sim" default="true"'))
    assert read_source(sim).where == '<node name="amcl_sim">' and read_source(sim).params["max_particles"] == 500


def test_nested_groups_and_a_nodes_own_condition_decide_whether_it_is_launched(tmp_path, capsys):
    from mcl.amcl_params import read_source

    p = _write(tmp_path, "nested.launch", """<launch>
  <arg name="a" default="1"/>
  <group if="$(arg a)">
    <group unless="$(arg a)">
      <node pkg="amcl" type="amcl" name="inner"><param name="min_particles" value="1"/></node>
    </group>
    <node pkg="amcl" type="amcl" name="off" if="false"><param name="min_particles" value="2"/></node>
  </group>
  <group unless="true"><group if="true"><node pkg="amcl" type="amcl" name="outer_off"/></group></group>
  <node pkg="map_server" type="map_server" name="map" if="$(eval arg('a') == 1)"/>
  <group>
    <node pkg="amcl" type="amcl" name="launched"><param name="min_particles" value="300"/></node>
  </group>
</launch>
""")
    src = read_source(p)
    assert src.where == '<node name="launched">' and src.params == {"min_particles": 300} and not src.warnings, src
    none = _write(tmp_path, "none.launch", SIM_OR_REAL.replace('<group unless="$(arg sim)">', '<group if="0">'))
    assert main(["config", "from-amcl", str(none)]) == 2
    line = _one_error(capsys)
    assert line.startswith(f"mcl: error: {none}: no <node pkg=\"amcl\"> is launched with the args' defaults: 2 amcl "
                           "nodes under an if= / unless= that is false"), line


def test_remaps_in_a_group_or_the_file_reach_the_nodes_after_them_and_a_nodes_own_win(tmp_path):
    # roslaunch applies a <remap> to the nodes declared after it in its scope (the file, a <group>); the node's own
    # remap comes last. Only the node's were read, so a robot's launch file that remaps scan for a whole group
    # gave no topics.scan
    def keys(body: str) -> dict:
        return convert(_write(tmp_path, "amcl.launch", f"<launch>\n{body}\n</launch>\n")).keys

    node = '<node pkg="amcl" type="amcl" name="amcl"><param name="min_particles" value="300"/></node>'
    assert keys(f'<remap from="scan" to="base_scan"/>\n{node}')["topics.scan"] == "/base_scan"
    assert "topics.scan" not in keys(f'{node}\n<remap from="scan" to="base_scan"/>')  # after the node: not its
    assert keys(f'<group><remap from="scan" to="front_scan"/>{node}</group>')["topics.scan"] == "/front_scan"
    sibling = f'<group><remap from="scan" to="other"/></group>\n<group>{node}</group>'
    assert "topics.scan" not in keys(sibling)  # a sibling group's remap stays in it
    own = ('<remap from="scan" to="base_scan"/>\n<node pkg="amcl" type="amcl" name="amcl">'
           '<remap from="scan" to="laser/scan"/><param name="min_particles" value="300"/></node>')
    assert keys(own)["topics.scan"] == "/laser/scan"
    assert "topics.scan" not in keys(f'<arg name="x" default="false"/><remap from="scan" to="a" if="$(arg x)"/>{node}')
    k = keys(f'<remap from="map" to="/static_map"/><remap from="scan" to="/robot/scan"/>{node}')
    assert k["topics.map"] == "/static_map" and k["topics.scan"] == "/robot/scan"


def test_a_namespaced_group_puts_the_nodes_topics_in_its_namespace(tmp_path):
    # <group ns="robot1"> (a multi-robot launch): AMCL there reads /robot1/scan and /robot1/map; a relative remap
    # resolves in the namespace, an absolute one stays
    def keys(body: str) -> dict:
        return convert(_write(tmp_path, "amcl.launch", f"<launch>\n{body}\n</launch>\n")).keys

    node = '<node pkg="amcl" type="amcl" name="amcl"><param name="min_particles" value="300"/></node>'
    k = keys(f'<arg name="robot" default="robot1"/><group ns="$(arg robot)">{node}</group>')
    assert k["topics.scan"] == "/robot1/scan" and k["topics.map"] == "/robot1/map"
    k = keys('<group ns="fleet"><group ns="r2"><remap from="scan" to="base_scan"/>'
             '<node pkg="amcl" type="amcl" name="amcl"><remap from="map" to="/map"/>'
             '<param name="min_particles" value="300"/></node></group></group>')
    assert k["topics.scan"] == "/fleet/r2/base_scan" and k["topics.map"] == "/map"
    k = keys('<node pkg="amcl" type="amcl" name="amcl" ns="/r3"><param name="min_particles" value="300"/></node>')
    assert k["topics.scan"] == "/r3/scan" and k["topics.map"] == "/r3/map"
    assert "topics.scan" not in keys(node)  # the root namespace: mcl's own choice (/scan, else the only one)


def test_a_rosparam_file_under_the_nodes_name_is_ros1_even_with_names_both_have(tmp_path):
    # `amcl:` without ros__parameters: is a rosparam file (nav2 never reads one so); with names both flavours share it
    # was read as nav2's, and nav2's defaults filled the group: kld_err 0.05 for ROS 1's 0.01, recovery_alpha_fast 0
    # (recovery not mapped) for ROS 1's 0.1. A flat file stays nav2's (said in a warning), as before.
    c = convert(_write(tmp_path, "ros1.yaml", "amcl:\n  min_particles: 100\n  max_particles: 5000\n"
                                              "  recovery_alpha_slow: 0.001\n"))
    assert c.keys["filter.kld_epsilon"] == 0.01
    assert c.keys["filter.recovery"] == "augmented" and c.keys["filter.recovery_alpha_fast"] == 0.1
    assert any("read as ROS 1 amcl's" in w for w in c.warnings)
    flat = convert(_write(tmp_path, "flat.yaml", "min_particles: 100\nmax_particles: 5000\n"))
    assert flat.keys["filter.kld_epsilon"] == 0.05 and any("read as nav2_amcl's" in w for w in flat.warnings)


@pytest.mark.parametrize("head, scan", [("/robot1/amcl:\n", "/robot1/scan"), ("robot1:\n amcl:\n", "/robot1/scan"),
                                        ("/fleet/r2/amcl:\n", "/fleet/r2/base_scan"), ("/**/amcl:\n", None)])
def test_a_nav2_nodes_namespace_takes_its_relative_topics(tmp_path, head, scan):
    # nav2 resolves a relative scan_topic in the node's namespace: /robot1/amcl read `scan` as /scan (the root)
    indent = " " * head.count("\n")
    topic = "base_scan" if "fleet" in head else "scan"
    text = f"{head}{indent} ros__parameters:\n{indent}  scan_topic: {topic}\n{indent}  max_particles: 3000\n"
    keys = convert(_write(tmp_path, "nav2.yaml", text)).keys
    if scan is None:  # a wildcard's namespace is not known: the root's
        assert keys["topics.scan"] == "/scan" and "topics.map" not in keys
    else:
        assert keys["topics.scan"] == scan and keys["topics.map"] == scan.rsplit("/", 1)[0] + "/map"


def test_a_launch_files_eval_is_named_whole_and_its_default_said_so(tmp_path):
    # `$(eval arg('particles') // 4)` was cut at its first ')' in the warning, and the output said min_particles
    # 100 "(AMCL's default)" as if the file had not set it
    c = convert(_write(tmp_path, "e.launch", '<launch><arg name="particles" default="1234"/>'
                                             '<node pkg="amcl" type="amcl" name="amcl">'
                                             '<param name="min_particles" value="$(eval arg(\'particles\') // 4)"/>'
                                             '<param name="max_particles" value="$(arg particles)"/></node></launch>'))
    assert any("$(eval arg('particles') // 4) cannot be resolved" in w for w in c.warnings), c.warnings
    assert "min_particles 100 (AMCL's default: the file's value could not be resolved)" in c.text


def test_the_random_floors_range_is_noted_with_its_factor(tmp_path):
    # AMCL divides z_rand by the laser's range, mcl by sensor.range_max: a stock nav2 file (laser_max_range 100)
    # against a 12 m laser has a floor 8.3 times lower in mcl; the note says so and how to match
    c = convert(_write(tmp_path, "n.yaml", "amcl:\n  ros__parameters:\n    laser_max_range: 100.0\n"
                                           "    z_hit: 0.5\n    z_rand: 0.5\n    sigma_hit: 0.2\n"))
    assert "mcl by sensor.range_max (100 m, from laser_max_range): for a laser of R m mcl's floor is R/100" in \
        " ".join(c.text.replace("# ", "").split())


def test_nav2_omni_model_keeps_the_books_roles(tmp_path):
    # nav2 omni_motion_model.cpp: rot std sqrt(alpha1 rot^2 + alpha2 trans^2), trans sqrt(alpha3 trans^2 + alpha4
    # rot^2), strafe sqrt(alpha4 rot^2 + alpha5 trans^2): mcl's omni model alpha for alpha (ROS 1's swaps 1 and 4)
    text = (NAV2.replace("nav2_amcl::DifferentialMotionModel", "nav2_amcl::OmniMotionModel")
            .replace("alpha1: 0.2", "alpha1: 0.5").replace("alpha4: 0.2", "alpha4: 0.01"))
    r = convert(_write(tmp_path, "nav2_omni.yaml", text))
    k = r.keys
    assert k["motion.model"] == "omni" and k["motion.alpha1"] == 0.5 and k["motion.alpha4"] == 0.01
    assert k["motion.alpha_strafe"] == 0.2 and not r.warnings


@pytest.mark.parametrize("written, radians", [("!degrees 10", math.radians(10)), ("deg(10)", math.radians(10)),
                                              ("!radians pi/6", math.pi / 6), ("rad(pi / 6)", math.pi / 6),
                                              ("!radians 0.25", 0.25), ("rad(2*pi/3)", 2 * math.pi / 3)])
def test_rosparam_angle_tags_are_radians(tmp_path, written, radians):
    # ros_comm rosparam reads !degrees / !radians and deg(...) / rad(...) (PAL's TIAGo amcl.yaml: !degrees 10)
    text = ROS1 + f"  update_min_a: {written}\n  laser_lambda_short: 0.1\n  laser_lambda_short: 0.1\n"
    r = convert(_write(tmp_path, "amcl.yaml", text))  # with a key given twice: read by the last-wins loader too
    assert r.keys["filter.update_min_a"] == pytest.approx(radians, abs=1e-6)


@pytest.mark.parametrize("written", ["!degrees ten", "!radians __import__('os')", "rad(2**2000)", "!radians pi/0"])
def test_a_bad_angle_is_one_error_line_naming_file_and_line(tmp_path, capsys, written):
    path = _write(tmp_path, "amcl.yaml", ROS1 + f"  update_min_a: {written}\n")
    assert main(["config", "from-amcl", str(path)]) == 2
    line = _one_error(capsys)
    assert f"{path}:31: invalid YAML" in line and "not" in line


def test_nav2_particle_counts_as_nav2_checks_them(tmp_path):
    # amcl_node.cpp initParameters: a negative max_particles is 2000, a negative min 500; then min > max raises max
    neg = convert(_write(tmp_path, "a.yaml", NAV2.replace("max_particles: 2000", "max_particles: -5")))
    assert neg.keys["filter.particles"] == 2000 and neg.keys["filter.min_particles"] == 500
    assert any("max_particles -5 is negative: nav2 sets it to 2000" in w for w in neg.warnings)
    up = convert(_write(tmp_path, "b.yaml", NAV2.replace("max_particles: 2000", "max_particles: 300")))
    assert up.keys["filter.particles"] == 500 and up.keys["filter.min_particles"] == 500
    # ROS 1 raises max only on a reconfigure: at start pf.c clamps the set to max_particles
    ros1 = convert(_write(tmp_path, "c.yaml", ROS1.replace("max_particles: 5000", "max_particles: 300")))
    assert ros1.keys["filter.particles"] == 300 and ros1.keys["filter.min_particles"] == 300
    assert any("never grows past max_particles" in w for w in ros1.warnings)


def test_nav2_random_seed_and_parameters_without_counterpart(tmp_path):
    r = convert(_write(tmp_path, "a.yaml", NAV2.replace("    z_short: 0.05\n", "    z_short: 0.05\n    random_seed: 7\n"
                                                         "    initialize_at_saved_pose: false\n"
                                                         "    freespace_downsampling: 2\n")))
    assert r.keys["seed"] == 7
    assert not any("not a nav2_amcl parameter" in w for w in r.warnings), r.warnings
    assert "freespace_downsampling 2" in r.text and "initialize_at_saved_pose false" in r.text
    random = convert(_write(tmp_path, "b.yaml", NAV2.replace("    z_short: 0.05\n", "    z_short: 0.05\n"
                                                              "    random_seed: -1\n")))
    assert "seed" not in random.keys and "random_seed -1: a new seed every run in nav2" in random.text
    ros1 = convert(_write(tmp_path, "c.yaml", ROS1 + "  std_warn_level_x: 0.2\n"))
    assert not any("not a ROS 1 amcl parameter" in w for w in ros1.warnings), ros1.warnings


def test_update_gating_is_a_group(tmp_path):
    # update_min_d alone: AMCL ran with its update_min_a default (ROS 1 pi/6), not mcl's
    r = convert(_write(tmp_path, "a.yaml", "amcl:\n  odom_model_type: diff-corrected\n  update_min_d: 0.3\n"))
    assert r.keys["filter.update_min_d"] == 0.3 and r.keys["filter.update_min_a"] == pytest.approx(math.pi / 6,
                                                                                                   abs=1e-6)


OUTER_LAUNCH = """\
<launch>
  <param name="amcl/max_particles" value="4000"/>
  <rosparam ns="amcl">
    odom_alpha1: 0.05
  </rosparam>
  <param name="other/max_particles" value="9"/>
  <group ns="robot1">
    <param name="amcl/min_particles" value="200"/>
    <node pkg="amcl" type="amcl" name="amcl">
      <param name="odom_model_type" value="diff-corrected"/>
      <rosparam ns="unused_ns">
        max_beams: 7
      </rosparam>
      <param from="$(find pkg)/amcl.yaml"/>
    </node>
  </group>
</launch>
"""


def test_launch_parameters_outside_the_node_that_name_it_are_read(tmp_path):
    # roslaunch sets every parameter before it starts the node: /robot1/amcl/min_particles is the node's; the
    # root's amcl/... are another node's (/amcl); a <rosparam ns> in the node puts its keys under ~ns/
    r = convert(_write(tmp_path, "amcl.launch", OUTER_LAUNCH))
    assert r.keys["filter.min_particles"] == 200 and r.keys["filter.particles"] == 5000  # AMCL's default max
    assert "motion.alpha1" not in r.keys or r.keys["motion.alpha1"] == 0.2
    assert "sensor.max_beams" not in r.keys
    assert any('<rosparam ns="unused_ns"> in the node' in w for w in r.warnings)
    assert any("<param from=" in w and "is not read" in w for w in r.warnings)
    root = convert(_write(tmp_path, "root.launch", OUTER_LAUNCH.replace('<group ns="robot1">', "<group>")))
    assert root.keys["filter.particles"] == 4000 and root.keys["motion.alpha1"] == 0.05
    assert root.keys["filter.min_particles"] == 200


def test_launch_parameters_in_document_order_at_the_root_in_other_groups_and_under_an_absolute_ns(tmp_path):
    # roslaunch: a root <rosparam file> holding amcl: {...}; a <group ns="amcl"> with no node; the later of two
    # declarations wins; <rosparam ns="/amcl"> in the node is the node's own namespace
    (tmp_path / "p.yaml").write_text("amcl:\n  min_particles: 123\n  kld_err: 0.02\n")
    text = """<launch>
  <rosparam file="p.yaml"/>
  <group ns="amcl"><param name="kld_z" value="0.95"/></group>
  <node pkg="amcl" type="amcl" name="amcl">
    <param name="max_particles" value="4000"/>
    <param name="odom_model_type" value="diff-corrected"/>
    <rosparam ns="/amcl">
      odom_alpha1: 0.07
    </rosparam>
  </node>
  <param name="amcl/max_particles" value="3000"/>
</launch>
"""
    r = convert(_write(tmp_path, "amcl.launch", text))
    k = r.keys
    assert k["filter.min_particles"] == 123 and k["filter.kld_epsilon"] == 0.02
    assert k["filter.kld_delta"] == pytest.approx(0.5 * math.erfc(0.95 / math.sqrt(2.0)), abs=1e-4)
    assert k["filter.particles"] == 3000  # the later declaration, after the node
    assert k["motion.alpha1"] == 0.07 and not any("unused_ns" in w or "not read" in w for w in r.warnings)


def test_a_huge_integer_in_an_amcl_file_is_one_error_line(tmp_path, capsys):
    path = _write(tmp_path, "amcl.yaml", ROS1 + "  laser_max_beams: 1" + "0" * 5000 + "\n")
    assert main(["config", "from-amcl", str(path)]) == 2
    assert "invalid YAML" in _one_error(capsys)
