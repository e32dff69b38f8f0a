"""dend for Blender: pose the active mesh with a dend server.

Vertex groups give the constraints (the group named in the panel's
"Fixed group", default `fixed`, and one handle per group whose name starts
with "Handle prefix", default `handle`). "Connect" uploads the mesh and
adds one empty per handle; "Follow" (a modal operator) sends the empties'
moves as drags and shows the pose frames live; "Save shape key" keeps the
settled pose as a named pose on the server and as a shape key.

"Apply skeleton poses" brings the named poses of a session on a rigged
character (the editor's Share link) onto the same character in Blender:
the poses fitted onto its joints as an action on the armature (one
keyframe and pose marker per pose) and each pose's corrective as a shape
key (`rig.py`).
"""

from __future__ import annotations

bl_info = {
    "name": "dend posing",
    "author": "dend",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > dend",
    "description": "Pose meshes with a dend server: handles as empties, live frames, results as shape keys",
    "category": "Animation",
}

from typing import Dict, Optional  # noqa: E402

import bpy  # noqa: E402

from .link import Link  # noqa: E402
from .rig import apply_skeleton, armature_of, parse_session_link  # noqa: E402
from .wire import DendError, Http  # noqa: E402

#: Live links by object name (one per mesh object).
LINKS: Dict[str, Link] = {}


def link_of(context: "bpy.types.Context") -> Optional[Link]:
    obj = context.active_object
    return LINKS.get(obj.name) if obj is not None else None


class DendSettings(bpy.types.PropertyGroup):
    server: bpy.props.StringProperty(name="Server", default="http://127.0.0.1:8080")
    fixed_group: bpy.props.StringProperty(name="Fixed group", default="fixed")
    handle_prefix: bpy.props.StringProperty(name="Handle prefix", default="handle")
    key_name: bpy.props.StringProperty(name="Shape key", default="dend pose")
    session_link: bpy.props.StringProperty(
        name="Session link", description="the editor's Share link of a session on this rigged character", default=""
    )


class DEND_OT_connect(bpy.types.Operator):
    """Upload the active mesh, set constraints from its vertex groups and add handle empties"""

    bl_idname = "dend.connect"
    bl_label = "Connect"

    def execute(self, context):
        st = context.scene.dend
        obj = context.active_object
        try:
            link = Link(st.server, obj)
            link.start(st.fixed_group, st.handle_prefix)
        except (DendError, OSError, ValueError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        LINKS[obj.name] = link
        self.report({"INFO"}, f"dend session {link.session}: {len(link.handles)} handle(s)")
        return {"FINISHED"}


class DEND_OT_follow(bpy.types.Operator):
    """Send handle moves and show the pose live (Esc to stop)"""

    bl_idname = "dend.follow"
    bl_label = "Follow"

    _timer = None

    def modal(self, context, event):
        link = link_of(context)
        if event.type == "ESC" or link is None:
            context.window_manager.event_timer_remove(self._timer)
            return {"CANCELLED"}
        if event.type == "TIMER":
            try:
                link.sync()
            except (DendError, OSError) as e:
                self.report({"ERROR"}, str(e))
                context.window_manager.event_timer_remove(self._timer)
                return {"CANCELLED"}
        return {"PASS_THROUGH"}

    def execute(self, context):
        if link_of(context) is None:
            self.report({"ERROR"}, "connect the active mesh first")
            return {"CANCELLED"}
        self._timer = context.window_manager.event_timer_add(1 / 30, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}


class DEND_OT_save_shape_key(bpy.types.Operator):
    """Save the settled pose as a named pose on the server and as a shape key"""

    bl_idname = "dend.save_shape_key"
    bl_label = "Save shape key"

    replace: bpy.props.BoolProperty(
        name="Replace", description="Replace a named pose and shape key of the same name", default=False
    )

    def invoke(self, context, event):
        # a name in use: ask before replacing it (the server refuses a save
        # over an existing pose unless told to replace it)
        obj = context.active_object
        keys = obj.data.shape_keys.key_blocks if obj is not None and obj.data.shape_keys else {}
        if context.scene.dend.key_name in keys:
            self.replace = True
            return context.window_manager.invoke_confirm(self, event)
        return self.execute(context)

    def execute(self, context):
        link = link_of(context)
        if link is None:
            self.report({"ERROR"}, "connect the active mesh first")
            return {"CANCELLED"}
        try:
            link.settle()
            link.save_shape_key(context.scene.dend.key_name, replace=self.replace)
        except (DendError, OSError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


def rigged_mesh(obj: "bpy.types.Object") -> Optional["bpy.types.Object"]:
    """The mesh an active object stands for: itself, or for an armature
    the mesh it deforms."""
    if obj is None:
        return None
    if obj.type == "MESH":
        return obj
    if obj.type == "ARMATURE":
        for child in obj.children:
            if child.type == "MESH" and armature_of(child) == obj:
                return child
    return None


class DEND_OT_apply_skeleton(bpy.types.Operator):
    """Fetch the session's named poses fitted onto the rig: an action on the armature and a corrective shape key per pose"""

    bl_idname = "dend.apply_skeleton"
    bl_label = "Apply skeleton poses"

    def execute(self, context):
        mesh = rigged_mesh(context.active_object)
        if mesh is None or armature_of(mesh) is None:
            self.report({"ERROR"}, "select a rigged mesh (with an Armature modifier) or its armature")
            return {"CANCELLED"}
        try:
            server, session, token = parse_session_link(context.scene.dend.session_link)
            data = Http(server, token).request(
                "GET", f"/v1/sessions/{session}/export?format=glb&as=skeleton-animation", raw=True
            )
            done = apply_skeleton(data, mesh)
        except (DendError, OSError, ValueError, KeyError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self.report({"INFO"}, f"{len(done['poses'])} pose(s) in action {done['action']}")
        return {"FINISHED"}


class DEND_PT_panel(bpy.types.Panel):
    bl_label = "dend"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "dend"

    def draw(self, context):
        st = context.scene.dend
        col = self.layout.column()
        for prop in ("server", "fixed_group", "handle_prefix"):
            col.prop(st, prop)
        col.operator("dend.connect")
        col.operator("dend.follow")
        col.prop(st, "key_name")
        col.operator("dend.save_shape_key")
        col.separator()
        col.prop(st, "session_link")
        col.operator("dend.apply_skeleton")


CLASSES = (DendSettings, DEND_OT_connect, DEND_OT_follow, DEND_OT_save_shape_key, DEND_OT_apply_skeleton, DEND_PT_panel)


def register() -> None:
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Scene.dend = bpy.props.PointerProperty(type=DendSettings)


def unregister() -> None:
    for link in LINKS.values():
        link.close()
    LINKS.clear()
    del bpy.types.Scene.dend
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
