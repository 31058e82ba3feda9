"""Build step that ships the package data in the wheel (everything else is in pyproject.toml).

``data/`` and ``workflow/schemas/config.schema.yaml`` stay at the repository root, where the Snakemake
workflow reads them. A wheel gets copies under ``lumbar/_resources/`` with the same relative layout, which
``lumbar.inputs.resources`` finds when the package is not running from a checkout. An editable install needs no
copy (it runs from ``src/``, and ``lumbar.inputs.resources`` finds the checkout).
"""
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
RESOURCES = ("data", "workflow/schemas/config.schema.yaml")   # repository-relative; a directory = all its files
TARGET = Path("lumbar") / "_resources"                      # inside the package (lumbar.inputs.resources._BUNDLED)


def resource_files() -> list[Path]:
    """The repository-relative files copied into the wheel."""
    out = []
    for rel in RESOURCES:
        src = ROOT / rel
        if src.is_dir():
            out += sorted(p.relative_to(ROOT) for p in src.rglob("*")
                          if p.is_file() and "__pycache__" not in p.parts)
        elif src.is_file():
            out.append(Path(rel))
        else:
            raise FileNotFoundError(f"package resource {rel} not found under {ROOT}")
    return out


class BuildPyWithResources(build_py):
    """build_py plus the copies of data/ and the config schema under lumbar/_resources/."""

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for rel in resource_files():
            dst = Path(self.build_lib) / TARGET / rel
            self.mkpath(str(dst.parent))
            self.copy_file(str(ROOT / rel), str(dst), preserve_mode=False)

    def get_outputs(self, include_bytecode=True):
        outputs = super().get_outputs(include_bytecode)
        if getattr(self, "editable_mode", False):
            return outputs
        return outputs + [str(Path(self.build_lib) / TARGET / rel) for rel in resource_files()]


setup(cmdclass={"build_py": BuildPyWithResources})
