"""Struct references: a state tuple as compiled code passes it, as one pointer.

To Numba a NamedTuple of arrays is a tuple of array structures: a kernel that takes one
gets every array as seven values in its signature, and a ``prange`` loop hands them all,
one by one, to the function it makes of its body. Such kernels take seconds each to
compile, a parallel one over the composites' state tuples 25–40 s (ARCHITECTURE.md, "What a
kernel compiles"). A StructRef (``numba.experimental.structref``) is one pointer.

The Python side keeps the NamedTuples (set-up, checkpoints, writers). A kernel makes a
StructRef over the *same* arrays, ``ClusterStateRef(*st)``, and passes that to its loops;
fields are read and written as on the tuple, and writes land in the tuple's arrays. A
kernel that reads a StructRef needs Numba's reference counting (no ``_nrt=False``).
"""
from __future__ import annotations

from numba.core import types
from numba.core.errors import TypingError
from numba.experimental import structref
from numba.extending import intrinsic


class FieldsType(types.StructRef):
    """Base of the StructRef types here: fields keep their array types (a constant passed
    to the constructor is not frozen into the type)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(t)) for name, t in fields)


def struct_ref(tuple_cls, module: str):
    """(``<Name>RefType``, ``<Name>Ref``): the Numba type and the constructor of a StructRef
    with the fields of NamedTuple ``tuple_cls``, ``<Name>Ref(*t)`` in compiled code. The
    module ``module`` must bind both under those names: Numba's cache pickles the type by
    its module and name."""
    name = f"{tuple_cls.__name__}Ref"
    type_cls = structref.register(type(f"{name}Type", (FieldsType,), {"__module__": module,
                                                                      "__qualname__": f"{name}Type"}))
    proxy = type(name, (structref.StructRefProxy,), {
        "__module__": module, "__qualname__": name,
        "__doc__": f"{tuple_cls.__name__}'s fields behind one pointer (grains/refs.py)."})
    structref.define_proxy(proxy, type_cls, tuple_cls._fields)
    return type_cls, proxy


@intrinsic
def as_tuple(typingctx, ref, cls):
    """The NamedTuple ``cls`` of a StructRef's fields (same names, same order), over the
    same arrays: for hot loops, which read a tuple's arrays as values held in registers
    where a StructRef's are loaded (and reference-counted) at every access."""
    if not isinstance(ref, types.StructRef) or not isinstance(cls, types.NamedTupleClass):
        return None
    fields = ref.field_dict
    names = tuple(fields)
    if names != tuple(cls.instance_class._fields):
        raise TypingError(f"as_tuple: the fields of {ref} are not those of {cls.instance_class.__name__}")
    tuple_type = types.BaseTuple.from_types([fields[n] for n in names], cls.instance_class)

    def codegen(context, builder, sig, args):
        data = structref._Utils(context, builder, ref).get_data_struct(args[0])
        values = []
        for name in names:
            value = getattr(data, name)
            context.nrt.incref(builder, fields[name], value)  # the tuple owns its arrays
            values.append(value)
        return context.make_tuple(builder, tuple_type, values)

    return tuple_type(ref, cls), codegen
