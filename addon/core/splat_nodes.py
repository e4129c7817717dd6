"""Node helpers shared by the splat import's two modes (splat_import.py's preview spheres and
splat_gaussian.py's Gaussians): node-group sockets across Blender 3.x-5.x, a node's live
output, the object + Geometry Nodes modifier, and a small expression builder over shader math
nodes.  Both modes import this module; it imports neither of them."""


def new_socket(ng, name, in_out, socket_type):
    """A node-group interface socket (ng.interface on 4.0+, ng.inputs/outputs on 3.x)."""
    if hasattr(ng, "interface"):  # Blender >= 4.0
        return ng.interface.new_socket(name=name, in_out=in_out, socket_type=socket_type)
    return (ng.inputs if in_out == "INPUT" else ng.outputs).new(socket_type, name)


def enabled_output(node, name):
    """The live output called `name` (3.x nodes keep one hidden socket per data type)."""
    return next(s for s in node.outputs if s.name == name and getattr(s, "enabled", True))


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

    def attr(self, name, output="Vector"):
        """An instance attribute written by Geometry Nodes (Instance on Points copies point attributes)."""
        a = self.n.new("ShaderNodeAttribute")
        a.attribute_type = "INSTANCER"
        a.attribute_name = name
        return a.outputs[output]
