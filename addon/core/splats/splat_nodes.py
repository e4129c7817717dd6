"""Node helpers shared by the splat import's modes (splat_import.py's preview spheres,
splat_gaussian.py's Gaussians and splat_billboard.py's camera quads): node-group sockets across
Blender 3.x-5.x, a node's live output, the instancing node group and the material scaffolding
the Gaussian and quad modes share, the object + Geometry Nodes modifier, and a small expression
builder over shader math nodes.  The modes import this module; it imports none of them."""


def new_socket(ng, name, in_out, socket_type):
    """A node-group interface socket (ng.interface on 4.0+, ng.inputs/outputs on 3.x)."""
    if hasattr(ng, "interface"):  # Blender >= 4.0
        return ng.interface.new_socket(name=name, in_out=in_out, socket_type=socket_type)
    return (ng.inputs if in_out == "INPUT" else ng.outputs).new(socket_type, name)


def enabled_output(node, name):
    """The live output called `name` (3.x nodes keep one hidden socket per data type)."""
    return next(s for s in node.outputs if s.name == name and getattr(s, "enabled", True))


def instance_node_group(name, material, make_mesh):
    """Geometry Nodes: vertices -> points -> an instance of the mesh node `make_mesh(nodes)` per
    point, rotated and scaled by the points' g_rot and g_scale, with `material`."""
    import bpy

    ng = bpy.data.node_groups.new(name, "GeometryNodeTree")
    new_socket(ng, "Geometry", "INPUT", "NodeSocketGeometry")
    new_socket(ng, "Geometry", "OUTPUT", "NodeSocketGeometry")
    n, link = ng.nodes, ng.links.new
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    to_points = n.new("GeometryNodeMeshToPoints")
    to_points.mode = "VERTICES"
    shape = make_mesh(n)
    set_mat = n.new("GeometryNodeSetMaterial")
    set_mat.inputs["Material"].default_value = material
    inst = n.new("GeometryNodeInstanceOnPoints")
    link(gin.outputs[0], to_points.inputs["Mesh"])
    link(shape.outputs["Mesh"], set_mat.inputs["Geometry"])
    link(to_points.outputs["Points"], inst.inputs["Points"])
    link(set_mat.outputs["Geometry"], inst.inputs["Instance"])
    for attr, sock in (("g_rot", "Rotation"), ("g_scale", "Scale")):
        a = n.new("GeometryNodeInputNamedAttribute")
        a.data_type = "FLOAT_VECTOR"
        a.inputs["Name"].default_value = attr
        link(enabled_output(a, "Attribute"), inst.inputs[sock])  # a vector into a 4.x Rotation socket is an Euler
    link(inst.outputs["Instances"], gout.inputs[0])
    for i, node in enumerate((gin, to_points, inst, gout)):
        node.location = (220 * i, 0)
    shape.location, set_mat.location = (220, -250), (440, -250)
    return ng


def new_material(name):
    """An empty node material and a ShaderExpr over its tree."""
    import bpy

    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    return mat, ShaderExpr(nt)


def emission_over_clear(b, colour, alpha):
    """The shader socket mix(transparent, emission of `colour`, alpha) (3DGS's one splat)."""
    emit = b.n.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    b.link(colour, emit.inputs["Color"])
    clear = b.n.new("ShaderNodeBsdfTransparent")
    mix = b.n.new("ShaderNodeMixShader")
    b.link(alpha, mix.inputs["Fac"])
    b.link(clear.outputs[0], mix.inputs[1])
    b.link(emit.outputs[0], mix.inputs[2])
    return mix.outputs[0]


def finish_material(mat, b, surface, columns):
    """Output `surface`, alpha blending for EEVEE Legacy, the nodes on a readable grid."""
    out = b.n.new("ShaderNodeOutputMaterial")
    b.link(surface, out.inputs["Surface"])
    if hasattr(mat, "blend_method"):  # EEVEE Legacy (3.x - 4.1): alpha blending, no shadows
        try:
            mat.blend_method = "BLEND"
            mat.shadow_method = "NONE"
        except (AttributeError, TypeError):
            pass
    for i, node in enumerate(b.n):
        node.location = (200 * (i % columns), -160 * (i // columns))
    return mat


def point_mesh(name, co, opacity, vectors):
    """A vertex-only mesh at `co` (N, 3) with a float `opacity` and a FLOAT_VECTOR point attribute
    per entry of `vectors` ({name: (N, 3)}): what the Gaussian and quad modes' modifiers read."""
    import bpy
    import numpy as np

    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(co))
    mesh.vertices.foreach_set("co", np.ascontiguousarray(co, dtype=np.float32).ravel())
    a = mesh.attributes.new("opacity", "FLOAT", "POINT")
    a.data.foreach_set("value", np.ascontiguousarray(opacity, dtype=np.float32))
    for key, arr in vectors.items():
        a = mesh.attributes.new(key, "FLOAT_VECTOR", "POINT")
        a.data.foreach_set("vector", np.ascontiguousarray(arr, dtype=np.float32).ravel())
    return mesh


def link_with_nodes(name, mesh, node_group, modifier, collection=None):
    """A new object for `mesh` in `collection` (default: the scene's) with a Geometry Nodes modifier."""
    import bpy

    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    (collection or bpy.context.scene.collection).objects.link(obj)
    mod = obj.modifiers.new(modifier, "NODES")
    mod.node_group = node_group
    return obj


class ShaderExpr:
    """Tiny expression builder over shader math nodes (scalar and vector)."""

    def __init__(self, nt):
        self.nt, self.n, self.link = nt, nt.nodes, nt.links.new

    def math(self, op, a, b=None, c=None):
        node = self.n.new("ShaderNodeMath")
        node.operation = op
        for i, v in enumerate((a, b, c)):
            if v is None:
                continue
            if isinstance(v, (int, float)):
                node.inputs[i].default_value = float(v)
            else:
                self.link(v, node.inputs[i])
        return node.outputs[0]

    def vmath(self, op, a, b=None, scale=None):
        node = self.n.new("ShaderNodeVectorMath")
        node.operation = op
        for i, v in enumerate((a, b)):
            if v is None:
                continue
            if isinstance(v, (tuple, list)):
                node.inputs[i].default_value = v
            else:
                self.link(v, node.inputs[i])
        if scale is not None:
            sock = node.inputs["Scale"] if "Scale" in node.inputs else node.inputs[3]
            if isinstance(scale, (int, float)):
                sock.default_value = float(scale)
            else:
                self.link(scale, sock)
        return node.outputs["Value"] if op in ("DOT_PRODUCT", "LENGTH", "DISTANCE") else node.outputs["Vector"]

    def mul(self, *xs):
        out = xs[0]
        for x in xs[1:]:
            out = self.math("MULTIPLY", out, x)
        return out

    def attr(self, name, output="Vector", kind="INSTANCER"):
        """An instance attribute written by Geometry Nodes (Instance on Points copies point
        attributes), or with kind="GEOMETRY" one of the (realized) mesh's own."""
        a = self.n.new("ShaderNodeAttribute")
        a.attribute_type = kind
        a.attribute_name = name
        return a.outputs[output]
