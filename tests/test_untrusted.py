"""Untrusted SSP archives (issue 14): refused with a package error naming member and element, nothing left behind.

Every crafted archive below is given to :class:`l1b2.cosim.master.CoSimulation`
with the temporary folder pointed at an empty ``tmp_path`` subfolder; the
test checks the exception class, that the one-line message names the archive,
the member and (where there is one) the XML element, and that the temporary
folder is empty afterwards (no extraction folder leaked).
"""

from __future__ import annotations

import io
import os
import re
import tempfile
import zipfile
from pathlib import Path

import pytest
from l1b2.cosim import ssp
from l1b2.cosim.master import CoSimulation
from l1b2.errors import ArchiveError, SourceOutsideError, SystemStructureError

COMPONENTS = ("Driver", "Stator", "Interface", "Slider")
SSD = "SystemStructure.ssd"
DRIVER_SSV = "resources/reference_motor/Driver.ssv"


@pytest.fixture
def tmpdir_watch(tmp_path, monkeypatch):
    """Point the temporary folder at an empty folder; returns it (checked empty after each refusal)."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


@pytest.fixture
def base_members(tmp_path) -> dict[str, bytes]:
    """The members of an ``L1B2Motor.ssp`` (stand-in FMU bytes: every refusal here comes before an FMU is read)."""
    fake = {}
    for name in COMPONENTS:
        p = tmp_path / f"{name}.fmu"
        p.write_bytes(b"not really an fmu")
        fake[name] = p
    out = ssp.build_ssp(tmp_path / "base" / "L1B2Motor.ssp", fake)
    with zipfile.ZipFile(out) as z:
        return {n: z.read(n) for n in z.namelist()}


def _write(path: Path, members: dict[str, bytes], compression=zipfile.ZIP_DEFLATED) -> Path:
    with zipfile.ZipFile(path, "w", compression) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def _ssd_replace(members, old, new):
    text = members[SSD].decode()
    assert old in text
    return {**members, SSD: text.replace(old, new, 1).encode()}


def _refused(archive, tmp_folder, exc_type=SystemStructureError, **kw) -> str:
    with pytest.raises(exc_type) as info:
        CoSimulation(archive, **kw)
    msg = str(info.value)
    assert "\n" not in msg
    assert not list(tmp_folder.iterdir()), f"left behind: {list(tmp_folder.iterdir())}"
    return msg


# ---------------------------------------------------------------------------
# Sources outside the archive
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("source", ["../x.fmu", "resources/../../x.fmu", "/tmp/x.fmu", "file:///tmp/x.fmu"])
def test_fmu_source_outside_the_archive_is_refused(tmp_path, tmpdir_watch, base_members, source):
    # reference: the brief - an absolute / climbing / URI source loads native code from outside the archive
    archive = _write(tmp_path / "L1B2Motor.ssp",
                     _ssd_replace(base_members, 'source="resources/Driver.fmu"', f'source="{source}"'))
    msg = _refused(archive, tmpdir_watch, SourceOutsideError)
    assert msg.startswith(f'{archive}: SystemStructure.ssd: <Component name="Driver"> source \'{source}\'')
    assert ("points outside the archive" in msg or "absolute path, outside the archive" in msg
            or "is a URI" in msg), msg


@pytest.mark.parametrize("source", ["../reference_motor/Driver.ssv", "/etc/passwd"])
def test_parameter_source_outside_the_archive_is_refused(tmp_path, tmpdir_watch, base_members, source):
    archive = _write(tmp_path / "L1B2Motor.ssp",
                     _ssd_replace(base_members, f'source="{DRIVER_SSV}"', f'source="{source}"'))
    msg = _refused(archive, tmpdir_watch, SourceOutsideError)
    assert msg.startswith(f'{archive}: SystemStructure.ssd: <Component name="Driver"> ParameterBinding '
                          f"source '{source}'"), msg
    assert "outside the archive" in msg


def test_source_outside_is_loaded_only_when_allowed(tmp_path, tmpdir_watch, base_members):
    # reference: allow_outside=True lifts the confinement: the next problem is then the stand-in FMU itself
    outside = tmp_path / "elsewhere" / "Driver.ssv"
    outside.parent.mkdir()
    outside.write_bytes(base_members[DRIVER_SSV])
    archive = _write(tmp_path / "L1B2Motor.ssp",
                     _ssd_replace(base_members, f'source="{DRIVER_SSV}"', f'source="{outside}"'))
    _refused(archive, tmpdir_watch, SourceOutsideError)
    msg = _refused(archive, tmpdir_watch, ArchiveError, allow_outside=True)
    assert "resources/Driver.fmu" in msg and "not a readable zip archive" in msg


def test_symlink_escape_from_the_ssd_folder_is_refused(tmp_path, base_members):
    # reference: a source that stays inside by name but is a symbolic link to a file outside
    folder = tmp_path / "system"
    (folder / "resources" / "reference_motor").mkdir(parents=True)
    for name, data in base_members.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(data)
    secret = tmp_path / "secret.ssv"
    secret.write_bytes(base_members[DRIVER_SSV])
    (folder / DRIVER_SSV).unlink()
    os.symlink(secret, folder / DRIVER_SSV)
    with pytest.raises(SourceOutsideError, match=r"resolves to .*secret\.ssv, outside the SSD's folder"):
        CoSimulation(folder)


# ---------------------------------------------------------------------------
# Size limits, compression bombs, corrupt archives
# ---------------------------------------------------------------------------

def test_compression_bomb_is_refused_before_extraction(tmp_path, tmpdir_watch, base_members):
    # reference: 64 MiB of zeros deflate to ~64 kB (ratio ~1000:1); the default limit is 100:1 above 1 MiB
    archive = _write(tmp_path / "L1B2Motor.ssp", {**base_members, "resources/bomb.bin": bytes(64 * 2**20)})
    assert archive.stat().st_size < 2**20
    msg = _refused(archive, tmpdir_watch, ArchiveError)
    assert msg.startswith(f"{archive}: resources/bomb.bin: unpacks ") and "compression bomb" in msg


def test_oversized_archive_is_refused(tmp_path, tmpdir_watch, base_members):
    # reference: the total unpacked size limit (ArchiveLimits.max_bytes), incompressible data
    big = os.urandom(3 * 2**20)
    archive = _write(tmp_path / "L1B2Motor.ssp", {**base_members, "resources/big.bin": big})
    limits = ssp.ArchiveLimits(max_bytes=2 * 2**20)
    msg = _refused(archive, tmpdir_watch, ArchiveError, limits=limits)
    assert msg == (f"{archive}: resources/big.bin: the archive unpacks to more than the limit of "
                   f"{2 * 2**20} bytes")
    assert ssp.DEFAULT_LIMITS.max_bytes == 256 * 2**20


def test_too_many_members_are_refused(tmp_path, tmpdir_watch, base_members):
    members = {**base_members, **{f"resources/junk/{i}.txt": b"x" for i in range(50)}}
    archive = _write(tmp_path / "L1B2Motor.ssp", members)
    msg = _refused(archive, tmpdir_watch, ArchiveError, limits=ssp.ArchiveLimits(max_members=40))
    assert msg == f"{archive}: {len(members)} members, more than the limit of 40"


def test_member_larger_than_its_header_is_refused(tmp_path, tmpdir_watch, base_members):
    # reference: a header that declares fewer bytes than the member holds (zipfile stops at the declared size,
    # the CRC then disagrees) - an error of ours, not zipfile.BadZipFile
    archive = _write(tmp_path / "L1B2Motor.ssp", {**base_members, "resources/liar.txt": b"y" * 5000},
                     zipfile.ZIP_STORED)
    data = bytearray(archive.read_bytes())
    with zipfile.ZipFile(archive) as z:
        info = z.getinfo("resources/liar.txt")
    size = (5000).to_bytes(4, "little")
    for pos in [m.start() for m in re.finditer(re.escape(size), bytes(data))]:
        data[pos:pos + 4] = (100).to_bytes(4, "little")      # file_size (and compress_size) in both headers
    archive.write_bytes(bytes(data))
    assert info.file_size == 5000
    with zipfile.ZipFile(archive) as z:
        assert z.getinfo("resources/liar.txt").file_size == 100    # the patched header is what zipfile sees
    msg = _refused(archive, tmpdir_watch, ArchiveError)
    assert msg.startswith(f"{archive}: not a readable zip archive (") and "liar.txt" in msg, msg


@pytest.mark.parametrize("damage", ["garbage", "truncated", "crc"])
def test_corrupt_archive_is_refused(tmp_path, tmpdir_watch, base_members, damage):
    archive = _write(tmp_path / "L1B2Motor.ssp", base_members, zipfile.ZIP_STORED)
    data = archive.read_bytes()
    if damage == "garbage":
        data = os.urandom(4096)
    elif damage == "truncated":
        data = data[: len(data) // 2]
    else:  # flip bytes inside the stored SSD: CRC mismatch on extraction
        pos = data.index(b"<ssd:System ")
        data = data[:pos] + b"<ssd:SYSTEM " + data[pos + 12:]
    archive.write_bytes(data)
    msg = _refused(archive, tmpdir_watch, ArchiveError)
    assert msg.startswith(f"{archive}: ") and ("not a readable zip archive" in msg), msg


@pytest.mark.parametrize("name", ["../evil.txt", "/abs/evil.txt", "a/../../evil.txt"])
def test_member_names_leaving_the_folder_are_refused(tmp_path, tmpdir_watch, base_members, name):
    # reference: zip-slip - refused, nothing written next to the extraction folder
    archive = _write(tmp_path / "L1B2Motor.ssp", {**base_members, name: b"evil"})
    msg = _refused(archive, tmpdir_watch, ArchiveError)
    assert f"member {name!r} would be written outside the extraction folder" in msg
    assert not (tmp_path / "evil.txt").exists()


def test_missing_archive_file_is_refused(tmp_path, tmpdir_watch):
    msg = _refused(tmp_path / "nowhere.ssp", tmpdir_watch, ArchiveError)
    assert msg == f"{tmp_path / 'nowhere.ssp'}: no such archive file"


# ---------------------------------------------------------------------------
# Missing members and bad values
# ---------------------------------------------------------------------------

def test_missing_ssd_is_refused(tmp_path, tmpdir_watch, base_members):
    archive = _write(tmp_path / "L1B2Motor.ssp", {k: v for k, v in base_members.items() if k != SSD})
    msg = _refused(archive, tmpdir_watch, ArchiveError)
    assert msg == f"{archive}: no SystemStructure.ssd at the root of the archive"


@pytest.mark.parametrize("member, element", [("resources/Slider.fmu", '<Component name="Slider">'),
                                             (DRIVER_SSV, '<Component name="Driver"> ParameterBinding')])
def test_missing_member_is_refused(tmp_path, tmpdir_watch, base_members, member, element):
    archive = _write(tmp_path / "L1B2Motor.ssp", {k: v for k, v in base_members.items() if k != member})
    msg = _refused(archive, tmpdir_watch)
    assert msg.startswith(f"{archive}: SystemStructure.ssd: {element} source '{member}'"), msg
    assert "no such member in the archive" in msg


@pytest.mark.parametrize("value, expected", [("abc", "a finite number"), ("nan", "a finite number"),
                                             ("", "a finite number")])
def test_bad_number_in_a_parameter_set_is_refused(tmp_path, tmpdir_watch, base_members, value, expected):
    text = base_members[DRIVER_SSV].decode()
    bad = re.sub(r'(<ssv:Parameter name="L_H">\s*<ssv:Real value=")[^"]*"', rf'\g<1>{value}"', text, count=1)
    assert bad != text
    archive = _write(tmp_path / "L1B2Motor.ssp", {**base_members, DRIVER_SSV: bad.encode()})
    msg = _refused(archive, tmpdir_watch)
    assert msg == (f"{archive}: {DRIVER_SSV}: <Parameter name=\"L_H\"> ssv:Real has value '{value}'; "
                   f"expected {expected}")


def test_bad_integer_and_boolean_values_are_refused(tmp_path):
    path = tmp_path / "p.ssv"
    for kind, raw, expected in (("Integer", "3.5", "an integer"), ("Boolean", "maybe", "true or false")):
        path.write_text(f'<ssv:ParameterSet xmlns:ssv="{ssp.NS["ssv"]}" version="1.0" name="p"><ssv:Parameters>'
                        f'<ssv:Parameter name="n"><ssv:{kind} value="{raw}"/></ssv:Parameter>'
                        "</ssv:Parameters></ssv:ParameterSet>")
        with pytest.raises(SystemStructureError) as info:
            ssp.read_ssv(path)
        assert str(info.value) == f"{path}: <Parameter name=\"n\"> ssv:{kind} has value '{raw}'; expected {expected}"
    path.write_text(f'<ssv:ParameterSet xmlns:ssv="{ssp.NS["ssv"]}" version="1.0" name="p"><ssv:Parameters>'
                    '<ssv:Parameter name="b"><ssv:Boolean value="true"/></ssv:Parameter>'
                    '<ssv:Parameter name="i"><ssv:Integer value="-3"/></ssv:Parameter>'
                    '<ssv:Parameter name="r"><ssv:Real/></ssv:Parameter>'
                    "</ssv:Parameters></ssv:ParameterSet>")
    with pytest.raises(SystemStructureError, match=r'<Parameter name="r"> ssv:Real has no value'):
        ssp.read_ssv(path)


@pytest.mark.parametrize("old, new, expected", [
    ('stopTime="0.3"', 'stopTime="soon"',
     "<DefaultExperiment> stopTime='soon' is not a non-negative finite number"),
    ('baseStepSize="', 'baseStepSize="-', "baseStepSize='-"),
    ('<ssd:Component name="Driver" type="application/x-fmu-sharedlibrary" source="resources/Driver.fmu">',
     '<ssd:Component name="Driver" type="application/x-fmu-sharedlibrary">',
     '<Component name="Driver"> has no \'source\' attribute'),
    ('<ssd:Component name="Stator"', '<ssd:Component name="Driver"',
     '<Component name="Driver"> appears twice'),
    ('startElement="Interface" startConnector="F_d" endElement="Slider"',
     'startElement="Nobody" startConnector="F_d" endElement="Slider"',
     "a connection names element 'Nobody', which is not a component of the system"),
])
def test_bad_ssd_is_refused(tmp_path, tmpdir_watch, base_members, old, new, expected):
    text = base_members[SSD].decode()
    assert old in text
    archive = _write(tmp_path / "L1B2Motor.ssp", _ssd_replace(base_members, old, new))
    msg = _refused(archive, tmpdir_watch)
    assert msg.startswith(f"{archive}: SystemStructure.ssd: ") and expected in msg, msg


def test_stand_in_fmu_is_refused_naming_member_and_component(tmp_path, tmpdir_watch, base_members):
    archive = _write(tmp_path / "L1B2Motor.ssp", base_members)
    msg = _refused(archive, tmpdir_watch, ArchiveError)
    assert msg.startswith(f'{archive}: resources/Driver.fmu (<Component name="Driver">): not a readable zip')


def test_fmu_bomb_inside_the_archive_is_refused(tmp_path, tmpdir_watch, base_members):
    # reference: an FMU is itself a zip: checked against the same limits before fmpy reads or unpacks it
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")
        z.writestr("binaries/linux64/Driver.so", bytes(32 * 2**20))
    archive = _write(tmp_path / "L1B2Motor.ssp", {**base_members, "resources/Driver.fmu": buf.getvalue()})
    msg = _refused(archive, tmpdir_watch, ArchiveError)
    assert msg.startswith(f'{archive}: resources/Driver.fmu (<Component name="Driver">): binaries/linux64/Driver.so')
    assert "compression bomb" in msg


def test_invalid_fmu_is_refused_naming_member_and_component(tmp_path, tmpdir_watch, base_members):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("nothing.txt", "no model description")
    archive = _write(tmp_path / "L1B2Motor.ssp", {**base_members, "resources/Driver.fmu": buf.getvalue()})
    msg = _refused(archive, tmpdir_watch)
    assert msg.startswith(f'{archive}: resources/Driver.fmu (<Component name="Driver">): not a valid FMU')


# ---------------------------------------------------------------------------
# Valid archives and the source tree (real FMUs: model descriptions only, nothing instantiated)
# ---------------------------------------------------------------------------

@pytest.mark.fmu
def test_valid_archive_loads_and_is_removed_on_close(tmp_path, tmpdir_watch, fmus):
    archive = ssp.build_ssp(tmp_path / "L1B2Motor.ssp", fmus)
    with CoSimulation(archive) as cs:
        assert cs.archive == archive and cs.system.where == f"{archive}: SystemStructure.ssd"
        assert len(list(tmpdir_watch.iterdir())) == 1          # the unpacked archive, while open
        assert set(cs.fmu_paths) == set(COMPONENTS)
    assert not list(tmpdir_watch.iterdir())
    cs = CoSimulation(archive)
    del cs                                                    # collected without close(): removed too
    import gc
    gc.collect()
    assert not list(tmpdir_watch.iterdir())


@pytest.mark.fmu
def test_failure_after_the_fmus_are_read_leaves_nothing(tmp_path, tmpdir_watch, fmus):
    # reference: a connector unit that disagrees with the FMU is found last in the constructor
    archive = ssp.build_ssp(tmp_path / "L1B2Motor.ssp", fmus)
    with zipfile.ZipFile(archive) as z:
        members = {n: z.read(n) for n in z.namelist()}
    old = '<ssd:Connector name="F_d" kind="output"><ssc:Real unit="N"/></ssd:Connector>'
    assert old in members[SSD].decode()
    bad = _write(tmp_path / "bad.ssp", _ssd_replace(members, old, old.replace('unit="N"', 'unit="N/m"')))
    msg = _refused(bad, tmpdir_watch)
    assert msg.startswith(f"{bad}: SystemStructure.ssd: ")


@pytest.mark.fmu
def test_source_tree_ssd_with_fmu_dir_still_works(fmu_dir):
    # reference: system_models/L1B2Motor.ssd names resources/X.fmu; the FMUs come from fmu_dir (legitimate)
    with CoSimulation(fmu_dir=fmu_dir) as cs:
        assert cs.archive is None
        assert {p.parent for p in cs.fmu_paths.values()} == {Path(fmu_dir)}
        assert cs.parameter_sources_["Driver.L_H"][1] == ssp.SSV_DIR / "Driver.ssv"


@pytest.mark.fmu
def test_absolute_fmu_sources_in_a_folder_need_allow_outside(tmp_path, fmus):
    text = ssp.SSD_FILE.read_text()
    for name in COMPONENTS:
        text = text.replace(f'source="resources/{name}.fmu"', f'source="{fmus[name]}"')
    folder = tmp_path / "system"
    folder.mkdir()
    (folder / "L1B2Motor.ssd").write_text(text)
    (folder / "reference_motor").mkdir()
    for name in COMPONENTS:
        (folder / "reference_motor" / f"{name}.ssv").write_bytes((ssp.SSV_DIR / f"{name}.ssv").read_bytes())
    with pytest.raises(SourceOutsideError, match=r'<Component name="Driver"> source .* is an absolute path'):
        CoSimulation(folder / "L1B2Motor.ssd")
    with CoSimulation(folder / "L1B2Motor.ssd", allow_outside=True) as cs:
        assert cs.fmu_paths["Driver"] == fmus["Driver"]


def test_build_ssp_refuses_sources_leaving_the_archive(tmp_path, base_members):
    ssd = tmp_path / "L1B2Motor.ssd"
    ssd.write_text(base_members[SSD].decode().replace(f'source="{DRIVER_SSV}"', 'source="../Driver.ssv"'))
    with pytest.raises(SourceOutsideError, match=r'<Component name="Driver"> source \'../Driver.ssv\''):
        ssp.build_ssp(tmp_path / "x.ssp", {n: tmp_path / f"{n}.fmu" for n in COMPONENTS}, ssd_path=ssd)
