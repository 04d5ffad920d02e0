"""TOC download in both generations, item parsing, and the on-disk cache keyed by CRC."""
from __future__ import annotations

import json
import os

import pytest

from crazyflie_driver.crtp.packet import CRTPPacket
from crazyflie_driver.errors import ProtocolError, UnknownName
from crazyflie_driver.protocol.toc import TocEntry, TocFetcher, parse_item
from crazyflie_driver.protocol.toccache import TocCache, default_cache_dir
from support.scripted_link import ScriptedLink, make_crazyflie


def table_link(replies):
    """A link answering uplink hex strings with given downlink payloads."""
    return ScriptedLink(responder=lambda p: [CRTPPacket.from_bytes(bytes.fromhex(r))
                                             for r in replies.get(p.to_bytes().hex(" "), [])])


def test_param_toc_v2_on_the_wire(tmp_path):
    link = table_link({
        "2c 03": ["2c 03 02 00 78 56 34 12"],
        "2c 02 00 00": ["2c 02 00 00 06" + b"pid_rate\0roll_kp\0".hex()],
        "2c 02 01 00": ["2c 02 01 00 48" + b"imu\0ok\0".hex()],
    })
    fetcher = TocFetcher(link, 2, "param", 2, cache=TocCache(str(tmp_path)))
    toc, info = fetcher.fetch()
    assert link.raw_sent() == ["2c 03", "2c 02 00 00", "2c 02 01 00"]
    assert (info.count, info.crc) == (2, 0x12345678)
    assert list(toc) == [TocEntry(0, "pid_rate", "roll_kp", "float", False),
                         TocEntry(1, "imu", "ok", "uint8_t", True)]
    assert toc.lookup("imu.ok").readonly
    assert os.path.exists(tmp_path / "param_12345678.json")


def test_log_toc_v1_on_the_wire():
    link = table_link({
        "5c 01": ["5c 01 02 ef be ad de 08 40"],
        "5c 00 00": ["5c 00 00 07" + b"pm\0vbat\0".hex()],
        "5c 00 01": ["5c 00 01 02" + b"stab\0thrust\0".hex()],
    })
    toc, info = TocFetcher(link, 5, "log", 1).fetch()
    assert link.raw_sent() == ["5c 01", "5c 00 00", "5c 00 01"]
    assert (info.count, info.crc, info.max_blocks, info.max_ops) == (2, 0xDEADBEEF, 8, 0x40)
    assert [(e.full_name, e.ctype) for e in toc] == [("pm.vbat", "float"), ("stab.thrust", "uint16_t")]


def test_log_toc_v2_item_with_16_bit_id():
    link = table_link({
        "5c 03": ["5c 03 01 00 00 00 00 00 10 80"],
        "5c 02 00 00": ["5c 02 00 00 08" + b"kf\0q\0".hex()],
    })
    toc, info = TocFetcher(link, 5, "log", 2).fetch()
    assert (info.max_blocks, info.max_ops) == (16, 128)
    assert toc.lookup("kf.q").ctype == "FP16"


def test_item_ids_above_255_in_v2():
    entry = parse_item("param", 2, bytes([2, 0x2C, 0x01, 0x0A]) + b"g\0n\0")
    assert entry == TocEntry(300, "g", "n", "uint32_t", False)


def test_reply_for_another_id_is_not_accepted():
    link = table_link({
        "2c 01": ["2c 01 01 00 00 00 00"],
        "2c 00 00": ["2c 00 05 08" + b"a\0b\0".hex(), "2c 00 00 08" + b"g\0n\0".hex()],
    })
    toc, _ = TocFetcher(link, 2, "param", 1).fetch()
    assert [e.full_name for e in toc] == ["g.n"]


def test_out_of_range_item_is_a_protocol_error():
    link = table_link({"2c 03": ["2c 03 01 00 00 00 00 00"], "2c 02 00 00": ["2c 02"]})
    with pytest.raises(ProtocolError, match="item 0 is out of range"):
        TocFetcher(link, 2, "param", 2).fetch()


def test_unknown_type_byte_is_refused():
    with pytest.raises(ProtocolError, match="unknown type byte 0x04"):
        parse_item("param", 2, bytes([2, 0, 0, 0x04]) + b"g\0n\0")
    with pytest.raises(ProtocolError, match="0x09"):
        parse_item("log", 2, bytes([2, 0, 0, 0x09]) + b"g\0n\0")


def test_unknown_name_names_it():
    cf, link, fw = make_crazyflie(12)
    cf.params.fetch_toc()
    with pytest.raises(UnknownName, match="'ring.nope'"):
        cf.params.toc.lookup("ring.nope", "parameter")


@pytest.mark.parametrize("version", [2, 12])
def test_second_connect_with_same_crc_downloads_no_items(tmp_path, version):
    cache = str(tmp_path / "cache")
    cf, link, fw = make_crazyflie(version, cache_dir=cache)
    first_params = cf.params.fetch_toc()
    first_logs = cf.log.fetch_toc()
    item_cmd = 2 if version >= 4 else 0
    assert sum(1 for p in link.sent if p.port in (2, 5) and p.channel == 0
               and p.data[0] == item_cmd) == len(fw.params) + len(fw.logs)

    cf2, link2, fw2 = make_crazyflie(version, cache_dir=cache)
    assert cf2.params.fetch_toc() == first_params
    assert cf2.log.fetch_toc() == first_logs
    toc_requests = [p.to_bytes().hex(" ") for p in link2.sent if p.channel == 0 and p.port in (2, 5)]
    info = "03" if version >= 4 else "01"
    assert toc_requests == ["2c " + info, "5c " + info]


def test_changed_crc_downloads_again(tmp_path):
    cf, link, fw = make_crazyflie(12, cache_dir=str(tmp_path))
    cf.params.fetch_toc()
    params = [("a", "b", "uint8_t", False, 1)]
    cf2, link2, fw2 = make_crazyflie(12, cache_dir=str(tmp_path), params=params)
    assert [e.full_name for e in cf2.params.fetch_toc()] == ["a.b"]
    assert "2c 02 00 00" in link2.raw_sent()


def test_corrupt_cache_file_is_ignored_and_rewritten(tmp_path):
    cf, link, fw = make_crazyflie(12, cache_dir=str(tmp_path))
    entries = cf.params.fetch_toc()
    path = tmp_path / ("param_%08X.json" % fw.crc("param"))
    path.write_text('{"format": 1, "entries": [[0, "x"')
    cf2, link2, _ = make_crazyflie(12, cache_dir=str(tmp_path))
    assert cf2.params.fetch_toc() == entries
    assert "2c 02 00 00" in link2.raw_sent()
    assert json.loads(path.read_text())["entries"][0] == [0, "pid_rate", "roll_kp", "float", False]


def test_cache_with_wrong_count_or_bad_entries_is_ignored(tmp_path):
    cache = TocCache(str(tmp_path))
    cache.store("log", 7, [TocEntry(0, "a", "b", "float")])
    assert cache.load("log", 7, 1) == [TocEntry(0, "a", "b", "float")]
    assert cache.load("log", 7, 2) is None
    assert cache.load("param", 7, 1) is None
    doc = json.loads((tmp_path / "log_00000007.json").read_text())
    doc["entries"][0][3] = "bogus_t"
    (tmp_path / "log_00000007.json").write_text(json.dumps(doc))
    assert cache.load("log", 7, 1) is None


def test_unwritable_cache_dir_does_not_fail(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    cache = TocCache(str(blocker / "sub"))
    cache.store("param", 1, [TocEntry(0, "a", "b", "float")])  # logged, not raised
    assert cache.load("param", 1) is None


def test_default_cache_dir(monkeypatch, tmp_path):
    monkeypatch.delenv("CRAZYFLIE_TOC_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert default_cache_dir() == os.path.join(str(tmp_path), "crazyflie_driver", "toc")
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert default_cache_dir() == os.path.join(str(tmp_path), "home", ".cache", "crazyflie_driver", "toc")
    monkeypatch.setenv("CRAZYFLIE_TOC_CACHE", str(tmp_path / "explicit"))
    assert default_cache_dir() == str(tmp_path / "explicit")


def numbered_items_link(count, drop=lambda n: False):
    """A V2 parameter TOC of ``count`` u8 items; the n-th uplink item request is lost when ``drop(n)``."""
    seen = []

    def respond(p):
        d = p.data
        if p.port != 2 or p.channel != 0:
            return []
        if d[:1] == b"\x03":
            return [CRTPPacket(2, 0, b"\x03" + count.to_bytes(2, "little") + b"\x01\x02\x03\x04")]
        seen.append(d)
        if drop(len(seen)):
            return []
        i = int.from_bytes(d[1:3], "little")
        return [CRTPPacket(2, 0, b"\x02" + d[1:3] + b"\x08" + b"g\x00v%d\x00" % i)]
    return ScriptedLink(responder=respond), seen


def test_items_past_255_pipelined_one_round_trip_each():
    link, seen = numbered_items_link(300)
    toc, info = TocFetcher(link, 2, "param", 2).fetch()
    assert [e.ident for e in toc] == list(range(300)) and toc.find("g.v299").ident == 299
    assert len(seen) == 300                                  # no request sent twice on a clean link
    assert link.stats.sent <= 300 + 1 + 4 + 2                # about one round trip per item, not two


def test_lost_item_requests_are_sent_again():
    link, seen = numbered_items_link(40, drop=lambda n: n % 7 == 0)
    toc, _ = TocFetcher(link, 2, "param", 2).fetch()
    assert [e.full_name for e in toc][-1] == "g.v39" and len(toc) == 40
    assert len(seen) > 40


def test_a_silent_crazyflie_times_out_naming_the_item():
    from crazyflie_driver.errors import LinkTimeout
    link, _ = numbered_items_link(10, drop=lambda n: n >= 3)
    with pytest.raises(LinkTimeout, match="parameter TOC item 2"):
        TocFetcher(link, 2, "param", 2, timeout=0.3).fetch()
