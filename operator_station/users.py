"""The station's users: ``studio --users FILE``, one ``name:role:hash`` a line, read as strictly as the token file.

Why a file and not accounts in a database: a cell has a handful of people (two engineers, the
shift's operators), the integrator keeps the file with the cell's other settings, and it is
checked at start, in one line naming the file and the line, like every other input.

The format::

    # who may use the station (lines starting with # and blank lines are skipped)
    anna:operator:scrypt$16384$8$1$<salt, base64>$<key, base64>
    ben:engineer:sha256$<salt, hex>$<sha256(salt + password), hex>

* ``name``: 1 to 64 letters, digits, ``.``, ``_`` or ``-``, each name once;
* ``role``: ``operator`` or ``engineer`` (:mod:`operator_station.access`);
* the password's hash: ``scrypt$N$r$p$SALT$KEY`` (:func:`hashlib.scrypt`, the recommended one: slow
  for a guesser) or ``sha256$SALT$HEX`` (salted SHA-256, for tools that make nothing else).

Make a line with ``python -m operator_station.users NAME ROLE`` (asks for the password twice).
The file must be a regular file of at most 64 KiB that only its owner may read (``chmod 600``),
the rule of ``--token-file``.  A password is compared in constant time; the salt keeps two users
with one password apart.
"""
from __future__ import annotations

import base64
import binascii
import getpass
import hashlib
import hmac
import os
import re
import secrets
import stat
import sys
from dataclasses import dataclass
from pathlib import Path

from operator_station.access import ROLES, AccessError

#: A user's name.
NAME = re.compile(r"[A-Za-z0-9._-]{1,64}")
#: Largest users file read.
MAX_FILE = 64 << 10
#: scrypt's cost parameters the station makes (N, r, p): about 16 MiB and 50 ms a try.
SCRYPT_COST = (16384, 8, 1)
#: The largest scrypt cost a file may ask (a line asking more would make every login a denial of service).
MAX_SCRYPT_N = 1 << 20
MAX_SCRYPT_RP = 64
#: The memory scrypt may use for one check (hashlib's default limit is 32 MiB; N=2**20 with r=8 needs 1 GiB).
SCRYPT_MEMORY = 1 << 30
#: A password's length at most (a longer one is refused, not hashed).
MAX_PASSWORD = 1024


@dataclass(frozen=True)
class User:
    name: str
    role: str
    scheme: str  # "scrypt" or "sha256"
    salt: bytes
    key: bytes
    cost: tuple[int, int, int] = SCRYPT_COST

    def checks(self, password: str) -> bool:
        """Whether ``password`` is this user's (constant time in the key's bytes)."""
        raw = password.encode("utf-8", "surrogatepass") if len(password) <= MAX_PASSWORD else b""
        if not raw:
            return False
        return hmac.compare_digest(key_of(self.scheme, raw, self.salt, self.cost), self.key)


def key_of(scheme: str, password: bytes, salt: bytes, cost: tuple[int, int, int] = SCRYPT_COST) -> bytes:
    if scheme == "scrypt":
        n, r, p = cost
        return hashlib.scrypt(password, salt=salt, n=n, r=r, p=p, maxmem=SCRYPT_MEMORY, dklen=32)
    return hashlib.sha256(salt + password).digest()


def hash_password(password: str, scheme: str = "scrypt") -> str:
    """The third field of a users line for ``password`` (a fresh random salt each time)."""
    salt = secrets.token_bytes(16)
    raw = password.encode("utf-8", "surrogatepass")
    if scheme == "sha256":
        return f"sha256${salt.hex()}${key_of('sha256', raw, salt).hex()}"
    n, r, p = SCRYPT_COST
    key = key_of("scrypt", raw, salt)
    return f"scrypt${n}${r}${p}${base64.b64encode(salt).decode()}${base64.b64encode(key).decode()}"


def parse_hash(text: str) -> tuple[str, bytes, bytes, tuple[int, int, int]]:
    """(scheme, salt, key, cost) of a hash field; ValueError saying what is wrong."""
    parts = text.split("$")
    if parts[0] == "sha256":
        if len(parts) != 3:
            raise ValueError("a sha256 hash is sha256$SALT$HEX")
        try:
            salt, key = bytes.fromhex(parts[1]), bytes.fromhex(parts[2])
        except ValueError:
            raise ValueError("a sha256 hash's salt and digest are hexadecimal") from None
        if len(key) != 32 or not salt:
            raise ValueError("a sha256 hash has a salt and a digest of 64 hexadecimal digits")
        return "sha256", salt, key, SCRYPT_COST
    if parts[0] == "scrypt":
        if len(parts) != 6:
            raise ValueError("an scrypt hash is scrypt$N$r$p$SALT$KEY")
        if not all(p.isdigit() and len(p) <= 8 for p in parts[1:4]):
            raise ValueError("scrypt's N, r and p are whole numbers")
        n, r, p = (int(x) for x in parts[1:4])
        if n < 2 or n & (n - 1) or n > MAX_SCRYPT_N or not 1 <= r <= MAX_SCRYPT_RP or not 1 <= p <= MAX_SCRYPT_RP or 128 * r * n > SCRYPT_MEMORY // 2:
            raise ValueError(f"scrypt's N must be a power of two up to {MAX_SCRYPT_N}, r and p 1 to {MAX_SCRYPT_RP}, within 512 MiB")
        try:
            salt, key = base64.b64decode(parts[4], validate=True), base64.b64decode(parts[5], validate=True)
        except (binascii.Error, ValueError):
            raise ValueError("an scrypt hash's salt and key are base64") from None
        if not salt or len(key) != 32:
            raise ValueError("an scrypt hash has a salt and a 32-byte key")
        return "scrypt", salt, key, (n, r, p)
    raise ValueError("the hash must be scrypt$... or sha256$... (make a line: python -m operator_station.users NAME ROLE)")


def parse_users(text: str, shown: str) -> dict[str, User]:
    """The users of a file's text; AccessError naming ``shown``, the line and the field at the first bad line."""
    users: dict[str, User] = {}
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = stripped.split(":")
        where = f"{shown}:{number}"
        if len(fields) != 3:
            raise AccessError(f"{where}: a line is name:role:hash, got {len(fields)} field(s)")
        name, role, hashed = fields
        if not NAME.fullmatch(name):
            raise AccessError(f"{where}: name {name[:80]!r} must be 1 to 64 letters, digits, '.', '_' or '-'")
        if name in users:
            raise AccessError(f"{where}: name {name!r} is given twice (each user once)")
        if role not in ROLES:
            raise AccessError(f"{where}: role {role[:80]!r} of {name!r} must be {' or '.join(ROLES)}")
        try:
            scheme, salt, key, cost = parse_hash(hashed)
        except ValueError as error:
            raise AccessError(f"{where}: hash of {name!r}: {error}") from None
        users[name] = User(name, role, scheme, salt, key, cost)
    if not users:
        raise AccessError(f"{shown}: no users (lines name:role:hash; make one: python -m operator_station.users NAME ROLE)")
    return users


def read_users_file(path: Path) -> dict[str, User]:
    """The users of ``path``: a regular file of at most 64 KiB, UTF-8, readable by its owner only."""
    shown = f"--users {path}"
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise AccessError(f"{shown}: not a file")
        if info.st_size > MAX_FILE:
            raise AccessError(f"{shown}: {info.st_size} bytes, over the {MAX_FILE} a users file may have")
        if os.name == "posix" and info.st_mode & 0o077:
            raise AccessError(f"{shown}: readable by other users (mode {stat.S_IMODE(info.st_mode):o}): chmod 600 {path}")
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise AccessError(f"{shown}: no such file") from None
    except UnicodeDecodeError as error:
        line = path.read_bytes()[:error.start].count(b"\n") + 1
        raise AccessError(f"{shown}:{line}: not UTF-8 text") from None
    except OSError as error:
        raise AccessError(f"{shown}: cannot read: {error.strerror or error}") from None
    return parse_users(text, shown)


def main(argv: list[str] | None = None) -> int:
    """``python -m operator_station.users NAME ROLE [--sha256]``: print a users line (the password asked twice)."""
    args = list(sys.argv[1:] if argv is None else argv)
    scheme = "sha256" if "--sha256" in args else "scrypt"
    args = [a for a in args if a != "--sha256"]
    if len(args) != 2 or not NAME.fullmatch(args[0]) or args[1] not in ROLES:
        sys.stderr.write(f"usage: python -m operator_station.users NAME {{{','.join(ROLES)}}} [--sha256]  (prints name:role:hash for --users)\n")
        return 2
    password = getpass.getpass(f"password for {args[0]}: ")
    if not password or password != getpass.getpass("again: "):
        sys.stderr.write("error: the two passwords differ (or are empty); nothing printed\n")
        return 1
    print(f"{args[0]}:{args[1]}:{hash_password(password, scheme)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
