"""A fit served with --credentials refuses, at the link, every session without them (real Zenoh), as a
search's coordinator does: its losses cannot be taken or forged by whoever reaches its port."""

from __future__ import annotations

import secrets

import pytest
import zenoh

from spinefarm.coordinator.service import zenoh_config
from spinefarm.protocol.credentials import load_credentials
from spinefarm.worker.fit.remote import FitNetwork
from tests.coordinator_tests.helpers import free_endpoint


def test_a_fit_listening_with_credentials_lets_in_only_sessions_that_hold_them(tmp_path):
    fitter_pw, worker_pw = secrets.token_hex(16), secrets.token_hex(16)
    (tmp_path / "all").write_text(f"fit:{fitter_pw}\nworker:{worker_pw}\n")
    (tmp_path / "worker").write_text(f"worker:{worker_pw}\n")
    (tmp_path / "wrong").write_text(f"worker:{secrets.token_hex(16)}\n")
    ep = free_endpoint()
    served = zenoh.open(FitNetwork(listen=[ep], credentials=load_credentials(tmp_path / "all")).config())
    try:
        for refused in (None, load_credentials(tmp_path / "wrong")):
            with pytest.raises(zenoh.ZError):
                zenoh.open(zenoh_config("client", connect=[ep], credentials=refused))
        zenoh.open(zenoh_config("client", connect=[ep], credentials=load_credentials(tmp_path / "worker"))).close()
    finally:
        served.close()
