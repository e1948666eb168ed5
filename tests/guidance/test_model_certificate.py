"""The service refuses a model without a passed convergence certificate unless its config allows it."""

from __future__ import annotations

import asyncio
import subprocess
import sys
from pathlib import Path

import pytest

from koopguide.base.modelfile import ModelFileError
from koopguide.guidance import settings
from koopguide.guidance.daemon import GuidanceDaemon
from koopguide.harness.mission import free_udp_port
from koopguide.model.certificate import certificate_ok
from koopguide.model.field import load_field
from koopguide.model.learn import trainer
from koopguide.model.learn.export import save
from tests.support.models import small_config


@pytest.fixture(scope="module")
def uncertified_model(tmp_path_factory: pytest.TempPathFactory, zshape) -> Path:
    cfg = small_config(convergence=None)  # the raw learned field: no Lyapunov limit, no certificate
    path = tmp_path_factory.mktemp("raw") / "raw.pt"
    save(path, trainer.train(zshape, cfg, seed=0), zshape, cfg)
    return path


def test_the_certificate_check_tells_certified_from_uncertified(zshape_model: Path, uncertified_model: Path):
    assert certificate_ok(load_field(zshape_model))[0]
    ok, why = certificate_ok(load_field(uncertified_model))
    assert not ok and "certificate" in why


def test_the_service_refuses_an_uncertified_model_before_opening_anything(uncertified_model: Path):
    cfg = settings.load(overrides={"mavlink": {"endpoint": f"udp:127.0.0.1:{free_udp_port()}"}})
    with pytest.raises(ModelFileError, match="refusing to guide with it"):
        asyncio.run(GuidanceDaemon.create(cfg, uncertified_model))


def test_allow_uncertified_lets_it_run_with_a_warning(uncertified_model: Path, caplog: pytest.LogCaptureFixture):
    cfg = settings.load(
        overrides={"allow_uncertified": True, "mavlink": {"endpoint": f"udp:127.0.0.1:{free_udp_port()}"}}
    )

    async def open_and_close() -> None:
        daemon = await GuidanceDaemon.create(cfg, uncertified_model)
        await daemon.close()

    asyncio.run(open_and_close())
    assert any("UNCERTIFIED MODEL" in r.getMessage() for r in caplog.records)


def test_koopguide_run_exits_2_with_one_line_on_an_uncertified_model(uncertified_model: Path):
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "koopguide",
            "run",
            "--model",
            str(uncertified_model),
            "--mavlink",
            f"udp:127.0.0.1:{free_udp_port()}",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "convergence certificate" in lines[0], result.stderr
