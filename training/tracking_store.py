"""The tracking store's local side: a tracking URI checked before MLflow touches it (the sqlite file, the database
driver, whether a local store exists), and a fresh sqlite store created whole or not at all.

Without the checks MLflow fails late and loudly: a `sqlite:///` path naming a folder retries for minutes ("unable to
open database file") and then raises; a text file raises sqlite's "file is not a database" from deep in a
migration; `mysql://` or `postgresql://` without the driver raises ModuleNotFoundError mid-connection. Each becomes
the house error here, in milliseconds, and nothing is created (not even the lock file beside the database).
A mistyped local URI would otherwise be a new, empty registry ("no registered bodyschema models", exit 0):
`check_local_store` refuses a store whose folder is missing, and a missing store where models are to be read.
"""

from __future__ import annotations

import base64
import errno
import logging
import os
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path

from mlflow import MlflowClient

from bodyschema import log
from bodyschema.errors import must_be

SQLITE_HEADER = b"SQLite format 3\x00"      # the first 16 bytes of every SQLite database file
# Python module SQLAlchemy imports for a database URL → the pip package that provides it
DRIVER_PACKAGES = {"MySQLdb": "mysqlclient", "pymysql": "PyMySQL", "psycopg": "psycopg[binary]",
                   "psycopg2": "psycopg2-binary", "pyodbc": "pyodbc", "pymssql": "pymssql",
                   "mysql": "mysql-connector-python", "asyncpg": "asyncpg", "pg8000": "pg8000"}
HINT = "Fix --tracking-uri or $MLFLOW_TRACKING_URI (unset it for the default sqlite:///<cwd>/mlflow.db)."
BARE_SCHEMES = ("databricks", "databricks-uc", "uc")    # tracking URIs MLflow takes without "://", not paths
_log = logging.getLogger(__name__)


def local_store(uri: str) -> Path | None:
    """The file or folder that is a local store: a `sqlite:///` database file, a `file:` or bare-path folder (MLflow's
    file store); None for a server, a database URL or an in-memory sqlite."""
    if uri.startswith("sqlite:"):
        path = uri[len("sqlite:///"):].split("?")[0] if uri.startswith("sqlite:///") else ""
        return Path(path) if path and path != ":memory:" else None
    parsed = urllib.parse.urlparse(uri)
    if parsed.scheme == "file":
        return Path(urllib.parse.unquote(parsed.path)) if parsed.path else None
    if (parsed.scheme == "" and uri not in BARE_SCHEMES) or len(parsed.scheme) == 1:   # a path; "C:" is a drive
        return Path(uri)
    return None


def check_local_store(uri: str, *, reads: bool, create: bool) -> None:
    """A local store (`local_store`) whose folder does not exist is the house error unless `create`, which makes the
    folder; so is a missing store itself when `reads` (a command that reads models: nothing can be there), unless
    `create`. A command that only writes (train, the demo) creates its store in an existing folder."""
    store = local_store(uri)
    if store is None:
        return
    shown = log.masked(uri)
    if not store.parent.is_dir():
        if not create:
            raise ValueError(must_be("tracking URI", "a store in an existing folder", shown,
                                     f"The folder {store.parent} does not exist: fix the path (an absolute sqlite "
                                     "path takes four slashes, sqlite:////home/me/mlflow.db), or pass --create to "
                                     "create it."))
        store.parent.mkdir(parents=True, exist_ok=True)
        _log.debug("created the folder %s of tracking store %s (--create)", store.parent, shown)
    if reads and not store.exists() and not create:
        raise ValueError(must_be("tracking URI", "an existing tracking store (this command reads registered models)",
                                 shown, f"{store} does not exist: run from the folder holding your mlflow.db, or "
                                 "point --tracking-uri or $MLFLOW_TRACKING_URI at it (train a model first to make "
                                 "one; --create makes an empty store)."))


class TrackingUnreachable(ConnectionError):
    """The tracking server did not answer within the timeout (an OSError, so the CLI reports it as one)."""


def server_request(uri: str, path: str = "/health") -> urllib.request.Request:
    """A GET of `path` on the server of http(s) URI `uri`, its user:password@ (if any) sent as HTTP basic auth, as
    MLflow 3 does (requests takes the credentials from the URL; MLFLOW_TRACKING_USERNAME/PASSWORD otherwise): the
    host is dialled without them (urllib would look up "user:password@host" as the host name)."""
    parts = urllib.parse.urlsplit(uri)
    userinfo, _, host = parts.netloc.rpartition("@")
    request = urllib.request.Request(urllib.parse.urlunsplit((parts.scheme, host, parts.path.rstrip("/") + path,
                                                              "", "")))
    if userinfo:
        user, _, password = userinfo.partition(":")
        token = f"{urllib.parse.unquote(user)}:{urllib.parse.unquote(password)}".encode()
        request.add_header("Authorization", "Basic " + base64.b64encode(token).decode())
    return request


def check_server(uri: str, timeout_s: float) -> None:
    """The http(s) tracking server `uri` answers within `timeout_s` seconds (any HTTP answer counts, an error page
    or a 401 included), else TrackingUnreachable; its password is never shown."""
    try:
        with urllib.request.urlopen(server_request(uri), timeout=timeout_s):
            pass
    except urllib.error.HTTPError:
        return                               # it answered (an error page is still an answer)
    except (urllib.error.URLError, OSError, ValueError) as error:
        reason = getattr(error, "reason", error)
        raise TrackingUnreachable(must_be("tracking server", f"answering within {timeout_s:g} s",
                                          f"{log.masked(uri)}: {reason}",
                                          "Start it (`mlflow server --host 127.0.0.1 --port <port>`), or unset "
                                          "MLFLOW_TRACKING_URI to use the local sqlite store.")) from None


def check_sqlite_store(db: Path, uri: str) -> None:
    """`db` (the file of a sqlite:/// URI) is an SQLite database, an empty file, or absent in an existing folder."""
    if db.is_dir():
        raise ValueError(must_be("tracking URI", "sqlite:///<a database file>", uri, f"{db} is a folder. {HINT}"))
    if db.exists():
        if not db.is_file():
            raise ValueError(must_be("tracking URI", "sqlite:///<a database file>", uri,
                                     f"{db} is not a regular file. {HINT}"))
        with open(db, "rb") as file:
            head = file.read(len(SQLITE_HEADER))
        if head and head != SQLITE_HEADER:       # an empty file is an empty database to SQLite
            raise ValueError(must_be("tracking URI", "sqlite:///<an SQLite database file>", uri,
                                     f"{db} exists and is not an SQLite database (it starts with {head[:8]!r}); "
                                     f"refusing to write MLflow's tables into it. {HINT}"))
        return
    if not db.parent.is_dir():
        raise ValueError(must_be("tracking URI", "sqlite:///<file> in an existing folder", uri,
                                 f"The folder {db.parent} does not exist: create it, or fix the path (an absolute "
                                 "path takes four slashes, sqlite:////home/me/mlflow.db)."))


def check_database_driver(uri: str) -> None:
    """The Python driver SQLAlchemy needs for a database URL (mysql://, postgresql://, mssql://) is installed."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    try:
        url = make_url(uri)
        shown = url.render_as_string(hide_password=True)          # the message must not print a password
        url.get_dialect().import_dbapi()
    except (ArgumentError, NoSuchModuleError, ValueError) as error:
        raise ValueError(must_be("tracking URI", "a database URL SQLAlchemy knows (dialect[+driver]://...)",
                                 uri.split("://")[0] + "://…", f"{error}. {HINT}")) from None
    except ImportError as error:
        module = (error.name or "").split(".")[0] or str(error)
        package = DRIVER_PACKAGES.get(module, module)
        raise ValueError(must_be(f"the database driver of tracking URI {shown}", "installed", f"no module {module}",
                                 f"Install it (`pip install {package}`), or use the default sqlite store "
                                 "(unset MLFLOW_TRACKING_URI).")) from None


def create_sqlite(db: Path) -> None:
    """Create a fresh store beside `db` and rename it into place: a kill while MLflow creates its ~40 tables then
    leaves no half-built database (the next process would die on "table ... already exists"), and a failure (a
    full disk) leaves no `.creating` file either."""
    partial = db.with_name(db.name + ".creating")
    _log.info(f"creating the tracking database {db} (once per store: MLflow builds its tables, seconds)")
    _remove_sqlite_files(partial)                         # of a creation killed before (a stale journal would be
    try:                                                  # rolled back into the new file)
        with log.quiet_mlflow(), log.timed(_log, f"created the tracking database {db}"):   # MLflow's INFO lines
            fresh = MlflowClient(f"sqlite:///{partial}", f"sqlite:///{partial}")
            fresh.search_experiments(max_results=1)
            fresh.search_registered_models(max_results=1)
        os.replace(partial, db)
    except BaseException as error:
        _remove_sqlite_files(partial)
        if _sqlite_write_failed(error):
            raise OSError(errno.ENOSPC, f"SQLite could not write: {_sqlite_reason(error)}", str(db)) from error
        raise


def _remove_sqlite_files(db: Path) -> None:
    for suffix in ("", "-journal", "-wal", "-shm"):
        db.with_name(db.name + suffix).unlink(missing_ok=True)


def _sqlite_write_failed(error: BaseException) -> bool:
    """A full disk or the file-size limit, as SQLite reports it (SQLITE_FULL, or an I/O error while writing)."""
    reason = _sqlite_reason(error)
    return "disk is full" in reason or "disk I/O error" in reason


def _sqlite_reason(error: BaseException) -> str:
    cause = error
    while cause is not None and type(cause).__module__ != "sqlite3":
        cause = cause.__cause__ or cause.__context__
    return str(cause if cause is not None else error).splitlines()[0]
