"""Config loading: defaults, overrides, and one clear error per bad key."""

import re

import pytest

from mcl.config import Config, dump_config, load_config
from mcl.errors import ConfigError


def write(tmp_path, text, name="c.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_defaults_without_a_file():
    cfg = load_config(None)
    assert cfg == Config()
    assert cfg.motion.noise_form == "variance"  # the book's form is the default
    assert cfg.filter.resampling == "systematic"


def test_default_yaml_lists_every_key():
    # configs/default.yaml documents every parameter: each must be present there.
    import yaml

    from mcl.config import PROJECT_ROOT, to_dict

    data = yaml.safe_load((PROJECT_ROOT / "configs" / "default.yaml").read_text())
    defaults = to_dict(Config())
    for section, value in defaults.items():
        assert section in data, section
        if isinstance(value, dict):
            assert set(data[section]) == set(value), section


def test_a_config_file_takes_default_yamls_values_for_the_keys_it_does_not_give(tmp_path):
    # A file with a map, a log and one key ran the code's plain values for the rest (a fixed 5,000 particles, no
    # recovery, kld off), though default.yaml and the dataset configs said missing keys take default.yaml's. Now
    # they do, but for the data keys (default.yaml's demo files are no part of another config).
    from mcl.config import PROJECT_ROOT

    default = load_config(PROJECT_ROOT / "configs" / "default.yaml")
    assert default.filter.particles != Config().filter.particles and default.filter.recovery != Config().filter.recovery
    p = write(tmp_path, "map: m.yaml\nlog: l.clf\nsensor:\n  likelihood_field:\n    sigma_hit: 0.3\n")
    cfg = load_config(p)
    assert cfg.sensor.likelihood_field.sigma_hit == 0.3
    assert cfg.map == str(tmp_path / "m.yaml") and cfg.truth is None  # its own data; not the demo's truth
    same = dump_config(cfg).replace(str(tmp_path / "m.yaml"), "M").replace(str(tmp_path / "l.clf"), "L")
    mine = load_config(PROJECT_ROOT / "configs" / "default.yaml", ["map=M", "log=L", "truth=null",
                                                                   "sensor.likelihood_field.sigma_hit=0.3"])
    assert same == dump_config(mine).replace(mine.map, "M").replace(mine.log, "L")
    # a pose alone tracks from it (default.yaml: global_localization false, a null pose is global)
    assert load_config(write(tmp_path, "filter:\n  initial_pose: [1, 2, 0]\n", "p.yaml")).filter.global_localization is False


def test_overrides_parse_yaml_values(tmp_path):
    cfg = load_config(None, ["sensor.likelihood_field.sigma_hit=0.2", "filter.particles=123",
                             "filter.initial_pose=[1, 2, 0.5]"])
    assert cfg.sensor.likelihood_field.sigma_hit == 0.2
    assert cfg.filter.particles == 123
    assert cfg.filter.initial_pose == (1.0, 2.0, 0.5)


def test_paths_resolve_relative_to_the_config_file(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "m.yaml").write_text("x")
    p = write(tmp_path, "map: sub/m.yaml\n")
    cfg = load_config(p)
    assert cfg.map == str((tmp_path / "sub" / "m.yaml").resolve())


def test_roundtrip_of_the_resolved_config(tmp_path):
    cfg = load_config(None, ["seed=7", "motion.alpha1=0.3", "sensor.laser_pose=[0.1, 0, 0]"])
    p = write(tmp_path, dump_config(cfg))
    assert load_config(p) == cfg


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("filter:\n  particels: 10\n", "filter.particels: unknown key (did you mean particles?)"),
        ("filter:\n  particles: many\n", "filter.particles: expected an integer"),
        ("filter:\n  particles: 0\n", "filter.particles: 0 is out of range"),
        ("sensor:\n  likelihood_field:\n    sigma_hit: 0\n", "sensor.likelihood_field.sigma_hit: 0.0 is out of range"),
        ("sensor:\n  beam:\n    z_hit: 1.5\n", "sensor.beam.z_hit: 1.5 is out of range"),
        ("motion:\n  noise_form: varience\n", "motion.noise_form: expected one of"),
        ("filter:\n  resampling: sytematic\n", "did you mean systematic?"),
        ("filter:\n  initial_pose: [1, 2]\n", "filter.initial_pose: expected"),
        ("filter: 3\n", "filter: expected a mapping"),
        ("motion:\n  map_rejection: 1\n", "motion.map_rejection: expected true or false"),
        ("sensor:\n  range_min: 5\n  range_max: 4\n", "sensor.range_min: 5.0 must be below sensor.range_max"),
        ("laser: FLASR\n", "laser: expected one of"),
        ("seeed: 1\n", "seeed: unknown key (did you mean seed?)"),
        ("- a\n- b\n", "expected a mapping"),
        ("filter:\n  particles: [1\n", "c.yaml:"),
    ],
)
def test_errors_name_the_file_and_key(tmp_path, text, fragment):
    p = write(tmp_path, text)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    msg = str(e.value)
    assert fragment in msg
    assert "c.yaml" in msg
    assert "\n" not in msg


def test_override_errors():
    with pytest.raises(ConfigError, match="expected section.key=value"):
        load_config(None, ["sensor.sigma_hit"])
    with pytest.raises(ConfigError, match="sensor.beam.sigma_hit: expected a number"):
        load_config(None, ["sensor.beam.sigma_hit=abc"])
    with pytest.raises(ConfigError, match="sensor.sigma: unknown key"):
        load_config(None, ["sensor.sigma=1"])


def test_exponent_notation_without_a_dot_is_a_number(tmp_path):
    # YAML 1.1 (PyYAML) resolves "1e-5" to a string; a user means the number, on the command line and in a file
    cfg = load_config(None, ["sensor.likelihood_field.sigma_hit=1e-1", "filter.kld_delta=5E-3"])
    assert cfg.sensor.likelihood_field.sigma_hit == 0.1 and cfg.filter.kld_delta == 0.005
    p = tmp_path / "c.yaml"
    p.write_text("sensor:\n  likelihood_field:\n    sigma_hit: 2e-1\n")
    assert load_config(p).sensor.likelihood_field.sigma_hit == 0.2
    with pytest.raises(ConfigError, match="sensor.beam.sigma_hit: expected a number"):
        load_config(None, ["sensor.beam.sigma_hit=1e"])  # not a number still says so


def test_a_bad_value_names_the_set_that_gave_it_else_the_file(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("sensor:\n  beam:\n    sigma_hit: 0.1\n    z_hit: abc\n")
    good = tmp_path / "good.yaml"
    good.write_text("sensor:\n  beam:\n    sigma_hit: 0.1\n")
    with pytest.raises(ConfigError) as e:
        load_config(good, ["sensor.beam.sigma_hit=-1"])
    assert str(e.value).startswith("--set sensor.beam.sigma_hit=-1: sensor.beam.sigma_hit: ") and "good.yaml" not in str(e.value)
    with pytest.raises(ConfigError) as e:
        load_config(p, ["sensor.beam.sigma_hit=-1"])  # the file is checked on its own first (issue 11)
    assert str(e.value).startswith(f"{p}:4: sensor.beam.z_hit: expected a number")  # with its line
    with pytest.raises(ConfigError) as e:
        load_config(p, ["sensor.beam.sigma_hit=0.2"])  # the file's own bad value
    assert str(e.value).startswith(f"{p}:4: sensor.beam.z_hit: expected a number")
    with pytest.raises(ConfigError) as e:
        load_config(None, ["filter.initial_std=[1, 2]"])
    assert str(e.value).startswith("--set filter.initial_std=[1, 2]: filter.initial_std: ")


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="nope.yaml: cannot read"):
        load_config(tmp_path / "nope.yaml")


def test_yaml_off_means_the_off_choice(tmp_path):
    # YAML 1.1 reads a bare `off` as false; rerun.mode must still be "off".
    assert load_config(write(tmp_path, "rerun:\n  mode: off\n")).rerun.mode == "off"
    assert load_config(None, ["rerun.mode=off"]).rerun.mode == "off"
    with pytest.raises(ConfigError, match="rerun.mode: expected one of"):
        load_config(None, ["rerun.mode=true"])


def test_an_error_a_set_causes_names_the_set(tmp_path):
    # An unknown section, a check across keys, the beam weights: the --set's doing, not the file's (nor the
    # default config's, which `mcl run` without a config passes).
    from mcl.config import PROJECT_ROOT

    base = write(tmp_path, "filter:\n  particles: 2000\nsensor:\n  range_max: 4\n", "base.yaml")
    for path in (base, PROJECT_ROOT / "configs" / "default.yaml", None):
        for sets, start in ((["nosuch.key=1"], "--set nosuch.key=1: nosuch: unknown key"),
                            (["sensor.range_min=100"], "--set sensor.range_min=100: sensor.range_min: 100.0 must be"),
                            (["sensor.model=beam", "sensor.beam.z_hit=0.9"], "--set sensor.beam.z_hit=0.9: sensor.beam."),
                            (["sensor={range_min: 100}"], "--set sensor={range_min: 100}: sensor.range_min: "),
                            (["filter.recovery=auto", "filter.recovery_alpha_fast=0.0001"],
                             "--set filter.recovery_alpha_fast=0.0001: filter.recovery_alpha_slow: "),
                            (["planes.depth=~no-such-user-mcl/d"], "--set planes.depth=~no-such-user-mcl/d: planes.depth: ")):
            with pytest.raises(ConfigError) as e:
                load_config(path, sets)
            assert str(e.value).startswith(start), (path, str(e.value))
    # of two keys a check compares, the one set last
    with pytest.raises(ConfigError, match=r"^--set sensor.range_max=3: sensor.range_min: 5.0 must be below"):
        load_config(None, ["sensor.range_max=3", "sensor.range_min=5", "sensor.range_max=3"])
    # a check the --set has no part in still names the file
    bad = write(tmp_path, "sensor:\n  range_min: 5\n  range_max: 4\n", "bad.yaml")
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(bad))}:2: sensor.range_min: 5.0 must be below"):
        load_config(bad, ["filter.particles=10"])
    assert load_config(bad, ["sensor.range_max=10"]).sensor.range_max == 10


def test_a_key_given_twice_is_an_error(tmp_path):
    # PyYAML keeps the last silently: a second filter block lost the first (initial pose and particles).
    from mcl.cli import main
    from mcl.errors import DataError
    from mcl.maps import load_map
    from mcl.yamlfile import read_yaml

    p = write(tmp_path, "seed: 2\nfilter:\n  particles: 2000\n  initial_pose: [0, 0, 0]\nfilter:\n"
                        "  resampling: stratified\n")
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(p))}:5: duplicate key filter$"):
        load_config(p)
    assert main(["config", "show", str(p)]) == 2
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(p))}:4: duplicate key particles$"):
        load_config(write(tmp_path, "filter:\n  particles: 1\n  kld: true\n  particles: 2\n"))
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(p))}:1: duplicate key seed$"):
        load_config(write(tmp_path, "{seed: 1, 'seed': 2}\n"))
    m = write(tmp_path, "image: map.pgm\nresolution: 0.05\nresolution: 0.5\norigin: [0, 0, 0]\n", "map.yaml")
    with pytest.raises(DataError, match=rf"^{re.escape(str(m))}:3: duplicate key resolution$"):
        load_map(m)
    # a merge key's keys are overridden by the mapping's own, as YAML means
    merged = write(tmp_path, "a: &f {particles: 10, kld: true}\nb: {<<: *f, particles: 20}\nc: {<<: [*f], kld: false}\n",
                   "m.yaml")
    assert read_yaml(merged, ConfigError) == {"a": {"particles": 10, "kld": True}, "b": {"particles": 20, "kld": True},
                                              "c": {"particles": 10, "kld": False}}


def test_the_yaml_loader_stays_libyaml_and_every_shipped_yaml_loads():
    # libyaml's parser reads a config 35 times faster than PyYAML's own (yamlfile.SAFE_LOADER)
    import yaml

    from mcl.config import PROJECT_ROOT
    from mcl.yamlfile import _Loader, read_yaml

    if hasattr(yaml, "CSafeLoader"):
        assert issubclass(_Loader, yaml.CSafeLoader)
    files = sorted((PROJECT_ROOT / "configs").glob("*.yaml")) + sorted((PROJECT_ROOT / "suites").glob("*.yaml"))
    assert files
    for f in files:
        assert read_yaml(f, ConfigError) == yaml.safe_load(f.read_text()), f


def test_a_yaml_file_not_utf8_says_so(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_bytes(b"seed: 1\n# caf\xe9\n")
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(p))}: not a UTF-8 text file$"):
        load_config(p)


def test_a_likelihood_field_with_z_hit_0_is_refused_unless_the_laser_is_off():
    # z_hit 0 made every pose score alike: the run went on as if without a laser (6.79 m on the demo), silently
    with pytest.raises(ConfigError, match=r"sensor.likelihood_field.z_hit: 0 makes every pose score alike"):
        load_config(None, ["sensor.likelihood_field.z_hit=0", "sensor.likelihood_field.z_rand=1"])
    # not read by the beam model, nor with the laser off (landmarks alone)
    assert load_config(None, ["sensor.likelihood_field.z_hit=0", "sensor.model=beam"]).sensor.model == "beam"
    assert not load_config(None, ["sensor.likelihood_field.z_hit=0", "sensor.use=false", "landmarks.use=true",
                                  "landmarks.map=m.yaml"]).sensor.use


def test_replace_validates_as_a_config_file_does():
    # mcl.config.replace was dataclasses.replace: alpha1=-1 failed three steps later ("math domain error"),
    # particles=0 as a ZeroDivisionError, a misspelt resampling inside the first resample
    from mcl.config import replace

    cfg = load_config(None)
    for section, kw, said in ((cfg.motion, {"alpha1": -1}, "motion.alpha1: -1.0 is out of range"),
                              (cfg.filter, {"particles": 0}, "filter.particles: 0 is out of range"),
                              (cfg.filter, {"particles": 1000.5}, "filter.particles: expected an integer"),
                              (cfg.filter, {"resampling": "sistematic"}, "did you mean systematic"),
                              (cfg, {"seed": -1}, "seed: -1 is out of range")):
        with pytest.raises(ConfigError, match=re.escape(said)):
            replace(section, **kw)
    assert replace(cfg.motion, alpha1=0.2).alpha1 == 0.2 and replace(cfg, seed=5) == Config(seed=5)


def test_replace_on_a_section_checks_across_its_keys():
    # replace(cfg.sensor.beam, z_hit=0.5) was taken: the beam model then scored with a mixture of total mass 0.7;
    # only replace on the whole Config checked the sum
    from mcl.config import replace

    cfg = load_config(None)
    for section, kw, said in (
            (cfg.sensor.beam, {"z_hit": 0.5}, "sensor.beam.z_hit: the beam model's mixture weights"),
            (cfg.sensor, {"range_min": 90.0}, "sensor.range_min: 90.0 must be below sensor.range_max"),
            (cfg.sensor.likelihood_field, {"z_hit": 0.0, "z_rand": 0.0}, "z_hit + z_rand must be positive"),
            (cfg.filter, {"recovery": "augmented", "recovery_alpha_slow": 0.5, "recovery_alpha_fast": 0.1},
             "filter.recovery_alpha_slow: 0.5 must be below"),
            (cfg.landmarks, {"use": True}, "landmarks.map: landmarks.use is true")):
        with pytest.raises(ConfigError, match=re.escape(said)):
            replace(section, **kw)
    beam = replace(cfg.sensor.beam, z_hit=0.7, z_short=0.2)  # a sum of 1 passes
    assert replace(cfg.sensor, beam=beam).beam.z_short == 0.2


def test_an_integer_with_leading_zeros_is_decimal_everywhere(tmp_path):
    # `--seed 010` ran seed 10, `--set seed=010` and a config's `seed: 010` seed 8 (YAML 1.1 octal), and `08` was
    # refused: one spelling, two trajectories. Now decimal in all three, as YAML 1.2 reads it.
    f = tmp_path / "c.yaml"
    f.write_text("seed: 010\nfilter:\n  particles: 0800\n")
    cfg = load_config(f, [])
    assert cfg.seed == 10 and cfg.filter.particles == 800
    assert load_config(None, ["seed=010"]).seed == 10 and load_config(None, ["seed=08"]).seed == 8
    assert load_config(None, ["seed=0x10"]).seed == 16  # an explicit base keeps it


def test_a_config_files_bad_key_names_its_line(tmp_path):
    # An unknown key, a value of the wrong type or out of range named the file and the key, not the line (a syntax
    # error and a duplicate key did): the key's line now, the deepest section the file gives otherwise.
    p = write(tmp_path, "seed: 3\nfilter:\n  kld: true\n  particels: 500\n", "typo.yaml")
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value) == f"{p}:4: filter.particels: unknown key (did you mean particles?)"
    p = write(tmp_path, "filter:\n  particles: 100\nsensor:\n  likelihood_field:\n    sigma_hit: -1\n", "r.yaml")
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value).startswith(f"{p}:5: sensor.likelihood_field.sigma_hit: -1.0 is out of range")


def test_an_empty_section_keeps_default_yamls_values(tmp_path):
    # `filter:` with every key commented out was read as the code's plain filter (5,000 fixed particles, no KLD,
    # no recovery) while `filter: {}` kept default.yaml's: the two spellings now agree, and so does a whole section
    # given by --set
    from mcl.config import default_config

    default = default_config()
    for text in ("filter:\n", "filter: {}\n", "filter:\nmotion:\n"):
        cfg = load_config(write(tmp_path, text))
        assert cfg.filter == default.filter and cfg.motion == default.motion, text
    cfg = load_config(write(tmp_path, ""), ["filter={particles: 300}"])
    assert cfg.filter.particles == 300 and cfg.filter.kld == default.filter.kld and cfg.filter.recovery == "lost"
    with pytest.raises(ConfigError, match=r"^--set filter=null: filter: is a section: set its keys"):
        load_config(write(tmp_path, ""), ["filter=null"])


@pytest.mark.parametrize("text,value", [("5e3", 5000), ("1E4", 10000), ("2.5e3", 2500), ("1.0e+4", 10000),
                                        ("50e-1", 5)])
def test_an_integer_key_takes_exponent_notation_as_a_float_key_does(tmp_path, text, value):
    assert load_config(write(tmp_path, f"filter:\n  particles: {text}\n")).filter.particles == value
    assert load_config(None, [f"filter.particles={text}"]).filter.particles == value


@pytest.mark.parametrize("text,msg", [
    ("filter:\n  particles: 1e20\n", "c.yaml:2: filter.particles: 100000000000000000000 is out of range (must be <= 10000000)"),
    ("filter:\n  particles: 2.5e1\n", None),  # 25: whole, accepted
    ("filter:\n  particles: 2.55e1\n", "c.yaml:2: filter.particles: expected an integer, got 25.5"),
    # YAML 1.1 read 1:30 as 90 (base 60)
    ("filter:\n  particles: 1:30\n", "c.yaml:2: filter.particles: expected an integer, got '1:30'"),
    ("motion:\n  alpha1: 1:30.5\n", "c.yaml:2: motion.alpha1: expected a number, got '1:30.5'"),
    # beyond Python's 4,300 digits: a ValueError traceback
    ("motion:\n  alpha1: " + "9" * 5000 + "\n", "c.yaml:2: invalid YAML: an integer of 5000 digits"),
    # hexadecimal escapes the 4,300-digit limit as it is read, then is a traceback as an error message prints it
    ("motion:\n  alpha1: 0x" + "F" * 4000 + "\n", "c.yaml:2: invalid YAML: an integer of 4002 digits"),
    ("filter:\n  particles: true\n", "c.yaml:2: filter.particles: expected an integer, got true"),
    ("filter:\n  initial_pose: [.nan, 0, 0]\n", "c.yaml:2: filter.initial_pose[0]: expected a finite number, got nan"),
    ("filter:\n  initial_pose: [nan, 0, 0]\n", "c.yaml:2: filter.initial_pose[0]: expected a number, got 'nan'"),
])
def test_numbers_a_user_writes_are_read_or_refused_in_one_line(tmp_path, text, msg):
    p = write(tmp_path, text)
    if msg is None:
        load_config(p)
        return
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value) == f"{tmp_path}/{msg}"


def test_an_error_line_shows_a_long_value_cut_short(tmp_path):
    # a 100,000-number list, a 200,000-character string: error lines of 500 kB
    for text in ("filter:\n  initial_pose: [" + "1.5, " * 100000 + "1]\n", "filter:\n  resampling: " + "x" * 200000):
        with pytest.raises(ConfigError) as e:
            load_config(write(tmp_path, text))
        assert len(str(e.value)) < 300, str(e.value)[:300]
    with pytest.raises(ConfigError) as e:
        load_config(None, ["seed=" + "9" * 5000])
    assert len(str(e.value)) < 400 and str(e.value).startswith("--set seed=999")


@pytest.mark.parametrize("text,hint", [
    ("filter.particles: 100\n", "filter.particles: unknown key (dotted keys are --set's; in a file, nest it: filter:, "
                                "then particles: indented under it)"),
    ("sensor:\n  likelihood_field.sigma_hit: 0.1\n", "sensor.likelihood_field.sigma_hit: unknown key (dotted keys are "
     "--set's; in a file, nest it: likelihood_field:, then sigma_hit: indented under it)"),
    ("particles: 100\n", "particles: unknown key (it belongs in filter.particles)"),
    ("filter:\n  alpha1: 0.1\n", "filter.alpha1: unknown key (it belongs in motion.alpha1)"),
    ("filter:\n  particels: 1\n", "filter.particels: unknown key (did you mean particles?)"),
    # a key's exact home before a near miss here (it said "did you mean cluster_size?")
    ("filter:\n  laser_pose: [0.1, 0, 0]\n", "filter.laser_pose: unknown key (it belongs in sensor.laser_pose)"),
    ("motion:\n  stall_ratio: 2\n", "motion.stall_ratio: unknown key (it belongs in"),
])
def test_a_key_in_the_wrong_place_says_where_it_belongs(tmp_path, text, hint):
    with pytest.raises(ConfigError) as e:
        load_config(write(tmp_path, text))
    assert str(e.value).endswith(hint) or hint.endswith("in") and hint in str(e.value), str(e.value)
