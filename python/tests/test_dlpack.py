"""The module's DLPack consumer against fake producers (dlpack_abi.py), everywhere (no device is
touched): the unversioned "dltensor" capsule of producers older than DLPack 1.0 and DLPack 1.0's
"dltensor_versioned", read through tsah._tsah._checked_device_array, the function every GpuRuntime
argument goes through. The module's own producer (tsah.DeviceArray) needs a device:
test_gpu_arrays.py."""
import pytest

import tsah
from dlpack_abi import IS_COPIED, READ_ONLY, FakeDlpack, FakeVersionedDlpack, capsule_name

check = tsah._tsah._checked_device_array

PRODUCERS = [FakeDlpack, FakeVersionedDlpack]


def test_dlpack_is_consumed_as_the_protocol_says():
    fake = FakeDlpack((4, 3), offset=16)
    got = check(fake, "origins", ["<f4"])
    assert got == {"data": 0x7000 + 16, "shape": (4, 3), "typestr": "<f4", "device": 0, "stream": None}
    assert fake.streams == [1]  # the legacy default stream, numbered 1 by the protocol
    assert capsule_name(fake.capsule) == b"used_dltensor"  # consumed: the capsule no longer deletes it
    assert fake.deleted == 1  # the consumer called the deleter once, when done
    check(fake, "origins", ["<f4"], stream=12345)
    assert fake.streams[-1] == 12345
    contiguous = FakeDlpack((4, 3), strides=(3, 1))
    assert check(contiguous, "origins", ["<f4"])["shape"] == (4, 3)


def test_versioned_dlpack_is_asked_for_and_consumed_as_the_protocol_says():
    fake = FakeVersionedDlpack((4, 3), offset=16)
    got = check(fake, "origins", ["<f4"], stream=12345)
    assert got == {"data": 0x7000 + 16, "shape": (4, 3), "typestr": "<f4", "device": 0, "stream": None}
    assert fake.max_versions == [(1, 0)] and fake.streams == [12345]
    assert capsule_name(fake.capsule) == b"used_dltensor_versioned"  # consumed: the capsule no longer deletes it
    assert fake.deleted == 1  # the versioned deleter, once, when done
    # A later minor version keeps the layout; explicit C-contiguous strides are fine.
    newer = FakeVersionedDlpack((4, 3), version=(1, 3), strides=(3, 1))
    assert check(newer, "origins", ["<f4"])["shape"] == (4, 3) and newer.deleted == 1


class UnversionedAnswer(FakeVersionedDlpack):
    """Takes max_version but returns the unversioned capsule (the protocol allows it)."""
    def __dlpack__(self, *, stream=None, max_version=None, dl_device=None, copy=None):
        self.max_versions.append(max_version)
        return FakeDlpack.__dlpack__(self, stream)


def test_an_unversioned_capsule_is_read_whatever_was_asked():
    fake = UnversionedAnswer((2, 3))
    assert check(fake, "origins", ["<f4"])["shape"] == (2, 3)
    assert fake.max_versions == [(1, 0)]
    assert capsule_name(fake.capsule) == b"used_dltensor" and fake.deleted == 1


class RecordedOldProducer(FakeDlpack):
    """A producer older than DLPack 1.0 that records the keywords it refused with TypeError."""
    def __init__(self, shape, error=None, **fields):
        super().__init__(shape, **fields)
        self.refused, self.error = [], error

    def __dlpack__(self, stream=None, **keywords):
        if keywords:
            self.refused.append(keywords)
            raise TypeError("__dlpack__() got an unexpected keyword argument 'max_version'")
        if self.error:
            raise self.error
        return super().__dlpack__(stream)


def test_producers_older_than_dlpack_1_are_asked_again_without_max_version():
    fake = RecordedOldProducer((2, 3))
    assert check(fake, "origins", ["<f4"], stream=7)["shape"] == (2, 3)
    assert fake.refused == [{"max_version": (1, 0)}]  # asked first with max_version
    assert fake.streams == [7]  # the second call, with the same stream
    assert capsule_name(fake.capsule) == b"used_dltensor" and fake.deleted == 1
    # The second call's own error is the caller's; an error other than TypeError is not retried.
    failing = RecordedOldProducer((2, 3), error=TypeError("stream 7 is not a stream"))
    with pytest.raises(TypeError, match="stream 7 is not a stream"):
        check(failing, "origins", ["<f4"], stream=7)
    assert len(failing.refused) == 1

    class Refusing(FakeVersionedDlpack):
        def __dlpack__(self, **keywords):
            self.max_versions.append(keywords.get("max_version"))
            raise BufferError("cannot export")
    refusing = Refusing((2, 3))
    with pytest.raises(BufferError, match="cannot export"):
        check(refusing, "origins", ["<f4"])
    assert refusing.max_versions == [(1, 0)]


@pytest.mark.parametrize("version", [(2, 0), (0, 8), (7, 1)])
def test_versioned_dlpack_of_another_major_version_is_refused_and_deleted(version):
    fake = FakeVersionedDlpack((4, 3), version=version)
    message = rf"origins: DLPack version {version[0]}\.{version[1]} is not supported \(major version 1\)"
    with pytest.raises(tsah.ConfigError, match=message):
        check(fake, "origins", ["<f4"])
    assert capsule_name(fake.capsule) == b"used_dltensor_versioned"
    assert fake.deleted == 1  # the protocol: the consumer still calls the deleter


@pytest.mark.parametrize("flag, message", [
    (READ_ONLY, r"out: the DLPack tensor is read-only"),
    (IS_COPIED, r"out: the DLPack tensor is a copy \(results written into it would be lost\)"),
])
def test_read_only_or_copied_dlpack_tensors_are_refused_as_outputs(flag, message):
    assert check(FakeVersionedDlpack((4,), flags=flag), "origins", ["<f4"])["shape"] == (4,)  # inputs are fine
    fake = FakeVersionedDlpack((4,), flags=flag)
    with pytest.raises(tsah.ConfigError, match=message):
        check(fake, "out", ["<f4"], writable=True)
    assert fake.deleted == 1
    assert check(FakeVersionedDlpack((4,)), "out", ["<f4"], writable=True)["shape"] == (4,)


@pytest.mark.parametrize("producer", PRODUCERS)
@pytest.mark.parametrize("fields, error, message", [
    ({"bits": 64}, tsah.ArgumentTypeError, "origins: expected a device array of typestr '<f4', got '<f8'"),
    ({"strides": (1, 4)}, tsah.ConfigError, "origins: must be C-contiguous"),
    ({"device": 1}, tsah.ConfigError, "origins: on CUDA device 1; the runtime uses device 0"),
    ({"code": 5}, tsah.ArgumentTypeError, "origins: a DLPack dtype numpy has no name for"),
])
def test_bad_dlpack_tensors_get_one_clear_line_and_are_deleted(producer, fields, error, message):
    fake = producer((4, 3), **fields)
    with pytest.raises(error, match=message):
        check(fake, "origins", ["<f4"])
    assert fake.deleted == (0 if "device 1" in message else 1)  # a consumed capsule is always deleted


def test_a_used_capsule_is_refused():
    class Reused(FakeVersionedDlpack):
        def __dlpack__(self, **keywords):
            return self.capsule
    fake = Reused((2, 3))
    FakeVersionedDlpack.__dlpack__(fake, max_version=(1, 0))
    check(fake, "origins", ["<f4"])
    with pytest.raises(tsah.ConfigError, match="origins: __dlpack__ did not return a DLPack capsule"):
        check(fake, "origins", ["<f4"])
    assert fake.deleted == 1
