import sys

import pytest

from avrisk.tensors.allocator import _user_configured, keep_freed_memory

linux_only = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="glibc's malloc is Linux's"
)


@linux_only
def test_the_thresholds_are_set_on_glibc():
    assert keep_freed_memory()


@pytest.mark.parametrize(
    "environ, configured",
    [
        ({}, False),
        ({"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2"}, False),
        ({"GLIBC_TUNABLES": "glibc.malloc.trim_threshold=0"}, True),
        ({"MALLOC_MMAP_THRESHOLD_": "131072"}, True),
        ({"MALLOC_TRIM_THRESHOLD_": "0"}, True),
    ],
)
def test_a_users_own_malloc_settings_are_left_alone(environ, configured):
    assert _user_configured(environ) is configured


def test_nothing_is_set_where_the_user_configured_malloc(monkeypatch):
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "131072")
    assert keep_freed_memory() is False
