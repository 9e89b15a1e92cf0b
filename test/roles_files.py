"""The files docs/faults.md's rows 320-329 name under {tmp}: the studio's users files, tokens and audit logs it refuses."""
from __future__ import annotations

#: A well-formed salted SHA-256 hash field (what the password is does not matter to a refusal).
HASH = "sha256$" + "ab" * 16 + "$" + "cd" * 32
GOOD = f"anna:operator:{HASH}\n"

ROLE_FILES: dict[str, str] = {
    "shared_users": GOOD,
    "users_fields": f"# the cell's people\nben:engineer\n{GOOD}",
    "users_role": f"anna:admin:{HASH}\n",
    "users_hash": "anna:operator:md5$0cc175b9c0f1b6a831c399e269772661\n",
    "users_twice": f"{GOOD}ben:engineer:{HASH}\n{GOOD}",
    "users_cost": "ben:engineer:scrypt$4194304$8$1$c2FsdA==$" + "A" * 43 + "=\n",
    "good_token": "G" * 43 + "\n",
}
#: Modes other than the owner's-only 600.
ROLE_MODES: dict[str, int] = {"shared_users": 0o644}
