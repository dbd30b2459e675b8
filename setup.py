"""Package discovery for the design card's layout: every package below the four source roots is installed, so a
new subpackage cannot be left out of the wheel (tests/test_packaging.py builds the wheel and imports every
module from it). Everything else is in pyproject.toml."""

from setuptools import find_packages, setup

# installed name -> source folder
ROOTS = {"tpnet_gpu": "tpnet_gpu", "tpnet_gpu.kernels": "kernels", "tpnet_gpu.net": "net", "tpnet_gpu.bench": "bench"}

packages, package_dir = [], {}
for name, folder in ROOTS.items():
    package_dir[name] = folder
    packages += [name] + [f"{name}.{sub}" for sub in find_packages(folder)]

setup(packages=packages, package_dir=package_dir)
