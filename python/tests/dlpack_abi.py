"""DLPack's ABI in ctypes, for the tests of the module's DLPack consumer and producer: the tensor
structs (the unversioned DLManagedTensor and DLPack 1.0's DLManagedTensorVersioned), the capsule
calls of Python's C API, and fake producers whose capsules point at a fake device address, so that
the module's checks run without a device."""
import ctypes


class DLDevice(ctypes.Structure):
    _fields_ = [("device_type", ctypes.c_int32), ("device_id", ctypes.c_int32)]


class DLDataType(ctypes.Structure):
    _fields_ = [("code", ctypes.c_uint8), ("bits", ctypes.c_uint8), ("lanes", ctypes.c_uint16)]


class DLTensor(ctypes.Structure):
    _fields_ = [("data", ctypes.c_void_p), ("device", DLDevice), ("ndim", ctypes.c_int32), ("dtype", DLDataType),
                ("shape", ctypes.POINTER(ctypes.c_int64)), ("strides", ctypes.POINTER(ctypes.c_int64)),
                ("byte_offset", ctypes.c_uint64)]


class DLManagedTensor(ctypes.Structure):
    pass


DELETER = ctypes.CFUNCTYPE(None, ctypes.POINTER(DLManagedTensor))
DLManagedTensor._fields_ = [("dl_tensor", DLTensor), ("manager_ctx", ctypes.c_void_p), ("deleter", DELETER)]


class DLPackVersion(ctypes.Structure):
    _fields_ = [("major", ctypes.c_uint32), ("minor", ctypes.c_uint32)]


class DLManagedTensorVersioned(ctypes.Structure):
    pass


VERSIONED_DELETER = ctypes.CFUNCTYPE(None, ctypes.POINTER(DLManagedTensorVersioned))
DLManagedTensorVersioned._fields_ = [("version", DLPackVersion), ("manager_ctx", ctypes.c_void_p),
                                     ("deleter", VERSIONED_DELETER), ("flags", ctypes.c_uint64),
                                     ("dl_tensor", DLTensor)]

READ_ONLY, IS_COPIED = 1, 2  # DLPACK_FLAG_BITMASK_READ_ONLY, DLPACK_FLAG_BITMASK_IS_COPIED


def new_capsule(struct, name):
    """A capsule of `struct` (kept alive by its owner) without a destructor."""
    new = ctypes.pythonapi.PyCapsule_New
    new.restype, new.argtypes = ctypes.py_object, [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p]
    return new(ctypes.addressof(struct), name, None)


def capsule_name(capsule):
    name = ctypes.pythonapi.PyCapsule_GetName
    name.restype, name.argtypes = ctypes.c_char_p, [ctypes.py_object]
    return name(capsule)


def capsule_struct(capsule, struct_type):
    """The struct a capsule points at, read under the capsule's own name."""
    pointer = ctypes.pythonapi.PyCapsule_GetPointer
    pointer.restype, pointer.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
    return struct_type.from_address(pointer(capsule, capsule_name(capsule)))


class FakeDlpack:
    """A DLPack producer older than DLPack 1.0 (its __dlpack__ takes no max_version) on CUDA device
    `device` whose capsule points at a fake address: the checks must refuse or accept it from the
    tensor's fields alone. Records the stream asked for and the deleter calls."""
    def __init__(self, shape, code=2, bits=32, strides=None, device=0, offset=0):
        self.deleted, self.streams, self.device = 0, [], device
        self.shape = (ctypes.c_int64 * len(shape))(*shape)
        self.strides = (ctypes.c_int64 * len(shape))(*strides) if strides else None
        self.deleter = DELETER(self._delete)
        self.managed = DLManagedTensor(
            DLTensor(0x7000, DLDevice(2, device), len(shape), DLDataType(code, bits, 1), self.shape,
                     self.strides if self.strides is not None else None, offset), None, self.deleter)

    def _delete(self, _):
        self.deleted += 1

    def __dlpack_device__(self):
        return (2, self.device)

    def __dlpack__(self, stream=None):
        self.streams.append(stream)
        self.capsule = new_capsule(self.managed, b"dltensor")
        return self.capsule


class FakeVersionedDlpack(FakeDlpack):
    """A DLPack 1.0 producer: the tensor of FakeDlpack in a "dltensor_versioned" capsule of `version`
    and `flags` when max_version's major is 1 or more, else unversioned. Records max_version too."""
    def __init__(self, shape, version=(1, 0), flags=0, **fields):
        super().__init__(shape, **fields)
        self.max_versions = []
        self.versioned_deleter = VERSIONED_DELETER(self._delete)
        self.versioned = DLManagedTensorVersioned(DLPackVersion(*version), None, self.versioned_deleter, flags,
                                                  self.managed.dl_tensor)

    def __dlpack__(self, *, stream=None, max_version=None, dl_device=None, copy=None):
        self.max_versions.append(max_version)
        if max_version is None or max_version[0] < 1:
            return super().__dlpack__(stream)
        self.streams.append(stream)
        self.capsule = new_capsule(self.versioned, b"dltensor_versioned")
        return self.capsule
