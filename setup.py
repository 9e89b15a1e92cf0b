"""Install script for colcon (ament_python) and for pip.

colcon reads ``data_files`` to lay out ``share/dual_arm_executive`` the way ``ros2 launch`` and
ament_index expect; pip installs the same files under ``<prefix>/share/dual_arm_executive``, where
:mod:`core_functions.resources` finds them when the source tree is not at hand.
"""
from __future__ import annotations

from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "dual_arm_executive"
#: The operator station's web server (python -m execution_engine studio).
STUDIO = ["starlette>=0.37", "uvicorn>=0.29", "websockets>=12"]
HERE = Path(__file__).resolve().parent


def tree(folder: str) -> list[tuple[str, list[str]]]:
    """Map every file below ``folder`` to the matching directory under share/<package>."""
    entries: dict[str, list[str]] = {}
    for path in sorted((HERE / folder).rglob("*")):
        if path.is_file() and "__pycache__" not in path.parts:
            rel = path.relative_to(HERE)
            entries.setdefault(str(Path("share") / PACKAGE / rel.parent), []).append(str(rel))
    return sorted(entries.items())


setup(
    name=PACKAGE,
    version="0.1.0",
    description="Skill-based execution of XML robot applications with one state machine per robot group",
    license="Apache-2.0",
    python_requires=">=3.10",
    packages=find_packages(
        include=["core_functions*", "node_transport*", "app_functions*", "execution_engine*", "robot_bridges*", "cell_runner*", "operator_station*"]
    ),
    package_data={
        **{f"robot_bridges.{sim}": ["urdf/*.urdf"] for sim in ("nextage_sim", "vplus", "kuka_rsi")},
        "operator_station": ["static/*.html", "static/*.css", "static/js/*.js", "static/vendor/*"],  # the page, served offline
    },
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/urdf", sorted(str(u.relative_to(HERE)) for u in HERE.glob("robot_bridges/*/urdf/*.urdf"))),
        *tree("launch"),
        *tree("config"),
        *tree("apps_xml"),
        *tree("schema"),
        *tree("interfaces"),
    ],
    install_requires=["lxml>=4.9", "numpy>=1.24", "pin>=2.7", "orjson>=3.9", "mcap>=1.2", "mcap-ros2-support>=0.5", "matplotlib>=3.6", "opencv-python-headless>=4.8", "pyyaml>=6"],
    extras_require={
        "studio": STUDIO,
        "dds": ["cyclonedds>=11,<12", "pyyaml>=6"],
        # pytest 9.2 keeps a test's id where pytest-xdist 3.8 cannot add its group to it: --dist loadgroup then
        # groups nothing (the RSI real-time tests ran beside each other, shared set-ups were made once per worker)
        "test": ["cyclonedds>=11,<12", "pytest>=7,<9.2", "hypothesis>=6.80", "pyyaml>=6", "jsonschema>=4.18", *STUDIO, "httpx>=0.24", "selenium>=4.11", "pytest-xdist>=3.5"],
    },
    zip_safe=True,
    entry_points={
        "console_scripts": [
            "execution_engine = cell_runner.nodes:engine_main",
            "group_machine = cell_runner.nodes:group_machine_main",
            "nextage_sim_bridge = cell_runner.bridge_nodes.nextage_sim:main",
            "vplus_bridge = cell_runner.bridge_nodes.vplus:main",
            "vplus_simulator = robot_bridges.vplus.simulator:main",
            "kuka_rsi_bridge = cell_runner.bridge_nodes.kuka_rsi:main",
            "ros2_control_bridge = cell_runner.bridge_nodes.ros2_control:main",
            "kuka_rsi_simulator = robot_bridges.kuka_rsi.simulator:main",
        ]
    },
)
