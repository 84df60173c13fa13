"""Packaging glue that pyproject.toml cannot express: the checkout's ``assets/`` folder (the one source of
truth for the package data) is mapped to the sub-package ``explorer.assets`` in both the wheel and an
editable install."""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["explorer", "explorer.*"]), "explorer.assets", "explorer.assets.dem",
              "explorer.assets.rpc", "explorer.assets.plotlyjs"],
    package_dir={"explorer.assets": "assets"},
    package_data={"explorer": ["py.typed", "kernel_manifest.json"], "explorer.assets": ["*.json", "*.md"],
                  "explorer.assets.dem": ["*"], "explorer.assets.rpc": ["*"], "explorer.assets.plotlyjs": ["*"]},
)
