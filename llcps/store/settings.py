"""The store's settings: text values by key (the current branch, the physics cache's bound)."""

from __future__ import annotations

from sqlalchemy import Connection, insert, select, update

from llcps.store.tables import Setting
from llcps.store.transactions import Transactions


class SettingQueries(Transactions):
    """Reading and writing a setting inside a transaction the caller holds."""

    @staticmethod
    def _get_setting(conn: Connection, key: str) -> str | None:
        return conn.scalar(select(Setting.value).where(Setting.key == key))

    @staticmethod
    def _set_setting(conn: Connection, key: str, value: str) -> None:
        if conn.execute(update(Setting).where(Setting.key == key).values(value=value)).rowcount == 0:
            conn.execute(insert(Setting).values(key=key, value=value))
