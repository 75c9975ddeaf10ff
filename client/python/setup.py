"""Generates nupmpc/v1 (the nupmpc.v1 stubs, with the messages' types in nupmpc_pb2.pyi)
into the build while pip builds the package; the metadata is in pyproject.toml."""

import pathlib
import shutil
import subprocess
import sys

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = pathlib.Path(__file__).resolve().parent
PROTO_ROOT = HERE.parent.parent / "proto"
PROTO = "nupmpc/v1/nupmpc.proto"


def generate(out_dir):
    if not (PROTO_ROOT / PROTO).exists():
        sys.exit(f"nupmpc: {PROTO_ROOT / PROTO} not found: build from a checkout (pip install client/python)")
    plugin = shutil.which("grpc_python_plugin")
    if shutil.which("protoc") and plugin:
        command = ["protoc", f"--plugin=protoc-gen-grpc_python={plugin}"]
    else:
        command = [sys.executable, "-m", "grpc_tools.protoc"]  # grpcio-tools
    subprocess.run(command + [f"--proto_path={PROTO_ROOT}", f"--python_out={out_dir}", f"--pyi_out={out_dir}",
                              f"--grpc_python_out={out_dir}",
                              str(PROTO_ROOT / PROTO)], check=True)


class BuildWithStubs(build_py):
    def run(self):
        super().run()
        generate(self.build_lib)


setup(cmdclass={"build_py": BuildWithStubs})
