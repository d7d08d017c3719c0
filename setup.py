"""Build step pyproject.toml cannot express: copy the user docs (docs/*.md, README.md) into the package
as spinefarm/docs, so `spinefarm docs` works from a wheel while docs/ stays where it is edited; and the
example gait files (examples/gaits/) as spinefarm/examples, which `spinefarm examples DIR` writes out."""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildPyWithDocs(build_py):
    def run(self) -> None:
        super().run()
        here = Path(__file__).resolve().parent
        target = Path(self.build_lib) / "spinefarm" / "docs"
        target.mkdir(parents=True, exist_ok=True)
        for md in [*sorted((here / "docs").glob("*.md")), here / "README.md"]:
            shutil.copy2(md, target / md.name)
        examples = Path(self.build_lib) / "spinefarm" / "examples"
        for gait in sorted((here / "examples").rglob("*.json")):
            (examples / gait.relative_to(here / "examples")).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(gait, examples / gait.relative_to(here / "examples"))


setup(cmdclass={"build_py": BuildPyWithDocs})
