"""The files docs/faults.md's rows 280-289 name under {tmp}: a checkpoint of a run whose remainder was edited while
paused (issue 26 item 3), and the application as it was before the edit, which a resume must refuse."""
from __future__ import annotations

import hashlib
import tempfile
from pathlib import Path

from execution_engine.checkpoint.store import CheckpointStore

MOVE = '<left_arm><function name="move_to_joint_pose"><params><param value="initial"/></params></function></left_arm>'


def _app(*ids: str) -> str:
    operations = "".join(f'  <operation id="{i}">{MOVE}</operation>\n' for i in ids)
    return f'<?xml version="1.0"?>\n<application name="edit_demo" robot="nextage">\n{operations}</application>\n'


OLD, NEW = _app("reach", "hold", "closer"), _app("reach", "hold", "wider", "right_in")


def _checkpoint() -> bytes:
    """A checkpoint whose run was edited after operation 'hold': its meta names edit_new.xml, as the engine leaves it."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "edited.checkpoint.sqlite"
        store = CheckpointStore(path)
        old = {"application": "edit_demo", "application_path": "edit_old.xml", "application_sha256": hashlib.sha256(OLD.encode()).hexdigest(),
               "cell_path": "", "cell_sha256": "", "robot": "nextage_open"}
        store.begin_run(old, "", "", "")
        new = {**old, "application_path": "edit_new.xml", "application_sha256": hashlib.sha256(NEW.encode()).hexdigest()}
        store.swap(3.5, 2, "hold", "0" * 64, "1" * 64, new)
        store.close()
        return path.read_bytes()


PAUSED_EDIT_FILES: dict[str, str | bytes] = {"edit_old.xml": OLD, "edited.checkpoint.sqlite": _checkpoint()}
