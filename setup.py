"""Build hook (everything else is in pyproject.toml): ship the repository's default configs and the demo inside
the package, so an installed wheel runs ``mcl run`` from any folder.

The files stay where a reader of the repository finds them (configs/, data/demo/: the one source of truth);
building a wheel copies them to ``mcl/_project/`` in the same layout, so the relative paths inside
``configs/default.yaml`` (``../data/demo/map.yaml``) hold there too. ``mcl.config.shipped`` reads the
repository's copy when there is one (a source tree, an editable install), else the package's through
importlib.resources.
"""

from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
SHIPPED = ["configs/default.yaml", "configs/baseline.yaml", "data/demo"]


class build_py_with_project_files(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):  # an editable install reads the repository's copies
            return
        dst = Path(self.build_lib) / "mcl" / "_project"
        for rel in SHIPPED:
            src = ROOT / rel
            for f in sorted(src.rglob("*") if src.is_dir() else [src]):
                if f.is_file():
                    out = dst / f.relative_to(ROOT)
                    out.parent.mkdir(parents=True, exist_ok=True)
                    self.copy_file(str(f), str(out), preserve_mode=False)


setup(cmdclass={"build_py": build_py_with_project_files})
