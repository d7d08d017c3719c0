"""`search` picks its coordinator's port itself; another process may take it before Zenoh binds it."""

from __future__ import annotations

import socket

from spinefarm.cli import search_loop
from spinefarm.cli.main import build_parser
from spinefarm.storage.hdf5_reader import read_run


def test_search_picks_another_port_when_its_own_is_taken_before_zenoh_binds_it(tmp_path, monkeypatch):
    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen()  # the race, forced: the first port the search picks is already someone's
    picks = iter([taken.getsockname()[1], taken.getsockname()[1]])
    real_free_port = search_loop.free_port
    monkeypatch.setattr(search_loop, "free_port", lambda *a: next(picks, None) or real_free_port(*a))
    out = tmp_path / "r.h5"
    args = build_parser().parse_args(["search", "sphere:3", "--trials", "4", "--workers", "1", "--out", str(out),
                                      "--api-port", "-1", "--quiet", "--sampler", "random"])
    try:
        assert search_loop.cmd_search(args) == 0
    finally:
        taken.close()
    _, cols = read_run(out)
    assert (cols["status"] == b"complete").sum() == 4


def test_a_taken_port_the_user_asked_for_is_an_error_that_names_it(tmp_path, capsys):
    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen()
    port = taken.getsockname()[1]
    out = tmp_path / "r.h5"
    args = build_parser().parse_args(["search", "sphere:3", "--trials", "4", "--workers", "1", "--out", str(out),
                                      "--api-port", "-1", "--quiet", "--listen", f"tcp/127.0.0.1:{port}"])
    try:
        search_loop.cmd_search(args)
        raise AssertionError("a search on a taken port started")
    except Exception as exc:
        assert str(port) in str(exc) and "already in use" in str(exc)
    finally:
        taken.close()
