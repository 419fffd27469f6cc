"""CPU kinds in records, the pinned BLAS / NumPy code paths of every step, the `status` bytes line."""

from holoflow.flow.executors.step_env import PINNED_ENV, bytes_note, cpu_facts, cpu_kind, isa_class
from holoflow.flow.executors.task import step_env  # the function (the package attribute may be the module)

V2 = {"cx16", "lahf_lm", "popcnt", "sse4_1", "sse4_2", "ssse3"}
V3 = V2 | {"avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave"}
V4 = V3 | {"avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"}


def test_isa_class_follows_the_psabi_levels():
    assert isa_class(set(), "x86_64") == "x86-64-v1"
    assert isa_class(V2, "x86_64") == "x86-64-v2"
    assert isa_class(V3 | {"avx512f"}, "x86_64") == "x86-64-v3"  # one v4 flag is not v4
    assert isa_class(V4 | {"avx512_bf16", "amx_tile"}, "x86_64") == "x86-64-v4+avx512_bf16+amx_tile"
    assert isa_class(V4, "aarch64") == "aarch64"
    facts = cpu_facts()
    assert set(facts) == {"vendor", "model", "isa"} and cpu_kind(facts).endswith(facts["isa"])


def test_every_step_gets_the_pins_unless_the_user_set_them(monkeypatch):
    for k in PINNED_ENV:
        monkeypatch.delenv(k, raising=False)
    env = step_env({"cpus": 1})
    assert {k: env[k] for k in PINNED_ENV} == PINNED_ENV and env["MKL_CBWR"] == "AVX2"
    monkeypatch.setenv("MKL_CBWR", "COMPATIBLE")
    assert step_env({"cpus": 1})["MKL_CBWR"] == "COMPATIBLE"


def test_status_bytes_line_names_the_kinds():
    here = cpu_kind(cpu_facts())
    assert bytes_note({"": ["a"]}) == ""  # records from before kinds
    assert f"this machine's CPU kind ({here})" in bytes_note({here: ["a", "b"]})
    mixed = bytes_note({here: ["a"], "GenuineIntel x86-64-v3": ["b"]})
    assert "GenuineIntel x86-64-v3 (b)" in mixed and "docs/store.md" in mixed
