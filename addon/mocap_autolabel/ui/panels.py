"""The Mocap tab of the 3D View sidebar: label a take, see what needs review, fix it, retarget the solved hands."""

from __future__ import annotations

import bpy

#: Icon of each keyframe type in the legend.
_KEY_ICONS = {"KEYFRAME": "KEYTYPE_KEYFRAME_VEC", "BREAKDOWN": "KEYTYPE_BREAKDOWN_VEC",
              "EXTREME": "KEYTYPE_EXTREME_VEC", "JITTER": "KEYTYPE_JITTER_VEC"}
#: Colour-set icon of each finger (Blender's bone colour set icons).
_FINGER_ICONS = {"THEME01": "COLORSET_01_VEC", "THEME02": "COLORSET_02_VEC", "THEME03": "COLORSET_03_VEC",
                 "THEME04": "COLORSET_04_VEC", "THEME06": "COLORSET_06_VEC", "THEME13": "COLORSET_13_VEC"}


class _Sidebar:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Mocap"


class MOCAPAL_UL_uncertain(bpy.types.UIList):
    """The review queue, what to look at first on top: labeled segments in doubt (label, raw trajectory, frames,
    confidence), then unlabeled pieces that may be a marker (trajectory, frames, how sure it is no marker)."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        row = layout.row(align=True)
        if item.unlabeled:
            row.label(text=item.point, icon="GHOST_ENABLED")
        else:
            row.label(text=f"{item.label}  {item.point}",
                      icon="KEYTYPE_EXTREME_VEC" if item.confidence < 0.5 else "KEYTYPE_BREAKDOWN_VEC")
        row.label(text=f"{item.frame_start}-{item.frame_end}")
        row.label(text=f"{item.confidence * 100:.1f} %" + (" no marker" if item.unlabeled else ""))


class MOCAPAL_UL_corrections(bpy.types.UIList):
    """The take's corrections in the order they were made: what, on which trajectory, which frames."""

    _ICONS = {"label": "LOCKED", "ghost": "GHOST_ENABLED", "split": "SCULPTMODE_HLT"}

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        layout.label(text=item.text, icon=self._ICONS.get(item.kind, "LOCKED"))


class MOCAPAL_PT_label(_Sidebar, bpy.types.Panel):
    bl_label = "Label"

    def draw(self, context):
        settings = context.scene.mocap_autolabel
        col = self.layout.column()
        col.use_property_split = True
        col.use_property_decorate = False
        col.operator("mocap_autolabel.import_markers", text="Import Take", icon="IMPORT")
        col.prop(settings, "take")
        col.prop(settings, "layout")
        row = col.row(align=True)
        row.prop(settings, "layout_file")
        row.operator("mocap_autolabel.make_layout", text="", icon="FILE_NEW")
        col.prop(settings, "method")
        col.prop(settings, "temporal")
        col.prop(settings, "hands")
        col.operator("mocap_autolabel.label", icon="SORTALPHA")
        col.operator("mocap_autolabel.solve_hand", icon="VIEW_PAN")
        col.operator("mocap_autolabel.export_hand", icon="EXPORT")


class MOCAPAL_UL_bone_map(bpy.types.UIList):
    """The Retarget panel's bone map: side, our bone, and the character's bone (picked from its bones)."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        row = layout.row(align=True)
        split = row.split(factor=0.45, align=True)
        split.label(text=f"{item.side[0].upper()}  {item.ours}", icon="BONE_DATA" if item.theirs else "BLANK1")
        arm = data.armature
        if arm is not None and arm.type == "ARMATURE":
            split.prop_search(item, "theirs", arm.data, "bones", text="")
        else:
            split.prop(item, "theirs", text="")

    def filter_items(self, context, data, propname):
        """The filter text matches our bone, the side or the character's bone."""
        items = getattr(data, propname)
        flags = [self.bitflag_filter_item] * len(items)
        text = self.filter_name.lower()
        if text:
            flags = [self.bitflag_filter_item if text in f"{i.side} {i.ours} {i.theirs}".lower() else 0
                     for i in items]
        return flags, []


class MOCAPAL_PT_retarget(_Sidebar, bpy.types.Panel):
    """Key the solved hands onto the animator's own character."""

    bl_label = "Retarget"
    bl_parent_id = "MOCAPAL_PT_label"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings = context.scene.mocap_autolabel.retarget
        layout = self.layout
        col = layout.column()
        col.use_property_split = True
        col.use_property_decorate = False
        col.prop(settings, "armature")
        col.prop(settings, "wrist")
        col.prop(settings, "reference")
        if settings.reference == "frame":
            col.prop(settings, "reference_frame")
        col.prop(settings, "pinch")
        if settings.convention:
            layout.label(text=f"Bone map ({settings.convention}):")
        row = layout.row()
        row.template_list("MOCAPAL_UL_bone_map", "", settings, "bone_map", settings, "bone_map_index", rows=6)
        side = row.column(align=True)
        side.operator("mocap_autolabel.retarget_auto_map", text="", icon="FILE_REFRESH")
        side.operator("mocap_autolabel.retarget_save_map", text="", icon="FILE_TICK")
        side.operator("mocap_autolabel.retarget_load_map", text="", icon="FILEBROWSER")
        op = layout.operator("mocap_autolabel.retarget", icon="ARMATURE_DATA")
        op.armature = settings.armature.name if settings.armature is not None else ""
        op.reference, op.reference_frame = settings.reference, settings.reference_frame
        op.wrist, op.pinch = settings.wrist, settings.pinch


class MOCAPAL_PT_review(_Sidebar, bpy.types.Panel):
    bl_label = "Review"

    def draw(self, context):
        from ..blender.review import first_frame, has_review, load_state, summary

        layout = self.layout
        settings = context.scene.mocap_autolabel
        if not has_review(settings.take):
            layout.label(text="Label a take to review it", icon="INFO")
            return
        state = load_state(settings.take)
        s = summary(state.labeling, settings.sure, first_frame(settings.take))
        box = layout.box()
        box.label(text=f"{settings.take.name}: {state.layout}, {state.method}, {state.temporal}")
        if s["hands"]:
            box.label(text=s["hands"])
        if s["hands_traded"]:
            box.label(text=s["hands_traded"], icon="INFO")
        if s["hands_warning"]:
            box.label(text=s["hands_warning"], icon="ERROR")
        if s["props"]:
            box.label(text=s["props"], icon="INFO")
        box.label(text=f"Labels present: {s['labels']}")
        box.label(text=f"Confident: {s['confident']:.1f} % of labeled samples")
        box.label(text=f"To review: {settings.uncertain_total} of {s['uncertain']} uncertain   Locked: {s['locked']}")
        if s["never_confident"] == "uncalibrated":  # no calibration for this layout: nothing is sure
            col = layout.box().column(align=True)
            col.label(text=f"{state.method} has no confidence calibration for this layout", icon="INFO")
            col.label(text="(its probabilities were never measured against the truth):")
            col.label(text="every segment is left for review")
        elif s["raw_confidence"] and state.method == "set":  # a layout set was never calibrated on
            col = layout.box().column(align=True)
            col.label(text="set has no confidence calibration for this layout:", icon="INFO")
            col.label(text="its raw probabilities seldom reach Confident at,")
            col.label(text="so the confident share says little: review the list")
        elif s["never_confident"]:  # calibrated, and honestly never sure: every segment is for review
            col = layout.box().column(align=True)
            col.label(text=f"{state.method} + {state.temporal} never rates a segment confident", icon="INFO")
            col.label(text="(none was right 99.9 % of the time in validation):")
            col.label(text="every segment is left for review; set is the method to trust")
        if s["layout_doubt"]:
            d = s["layout_doubt"]
            col = layout.box().column(align=True)
            col.label(text=f"Is this a {d.better} take?", icon="ERROR")
            col.label(text=f"{d.better}: {100 * d.better_share:.0f} % confident")
            col.label(text=f"{d.layout}: {100 * d.share:.0f} % confident")
            op = col.operator("mocap_autolabel.label", text=f"Label as {d.better}", icon="FILE_REFRESH")
            op.layout = d.better  # the operator's own layout wins over the panel's
            op.use_as_panel_layout = True
        row = layout.row(align=True)
        row.operator("mocap_autolabel.next_uncertain", text="Previous", icon="TRIA_LEFT").previous = True
        row.operator("mocap_autolabel.next_uncertain", text="Next", icon="TRIA_RIGHT").previous = False
        layout.operator("mocap_autolabel.jump_to_worst", text="Worst Frames", icon="ERROR")  # see the Timeline
        row = layout.row(align=True)
        row.prop(settings, "queue_labeled_only", toggle=True)
        sub = row.row(align=True)
        sub.active = not settings.queue_labeled_only
        sub.prop(settings, "queue_min_frames")
        layout.template_list("MOCAPAL_UL_uncertain", "", settings, "uncertain", settings, "uncertain_index", rows=6)
        if settings.uncertain_total > len(settings.uncertain):
            layout.label(text=f"Showing the first {len(settings.uncertain)} of {settings.uncertain_total}")
        if settings.uncertain_hidden:
            layout.label(text=f"{settings.uncertain_hidden} more uncertain: short unlabeled pieces (ghosts)"
                         if not settings.queue_labeled_only else f"{settings.uncertain_hidden} unlabeled left out",
                         icon="GHOST_DISABLED")
        layout.prop(settings, "sure", slider=True)


class MOCAPAL_PT_corrections(_Sidebar, bpy.types.Panel):
    bl_label = "Corrections"
    bl_parent_id = "MOCAPAL_PT_review"

    def draw(self, context):
        settings = context.scene.mocap_autolabel
        layout = self.layout
        if not settings.corrections:
            layout.label(text="No corrections yet")
            return
        row = layout.row()
        row.template_list("MOCAPAL_UL_corrections", "", settings, "corrections", settings, "corrections_index",
                          rows=4)
        row.column(align=True).operator("mocap_autolabel.delete_correction", text="", icon="X")


class MOCAPAL_PT_relabel(_Sidebar, bpy.types.Panel):
    bl_label = "Relabel"
    bl_parent_id = "MOCAPAL_PT_review"

    def draw(self, context):
        settings = context.scene.mocap_autolabel
        col = self.layout.column(align=True)
        col.operator("mocap_autolabel.assign_label", icon="SORTALPHA")
        col.operator("mocap_autolabel.swap_labels", icon="UV_SYNC_SELECT")
        col.operator("mocap_autolabel.unlabel", icon="GHOST_ENABLED")
        col.operator("mocap_autolabel.split", icon="SCULPTMODE_HLT")
        col.operator("mocap_autolabel.lock", icon="LOCKED")
        col.operator("mocap_autolabel.unlock", icon="UNLOCKED")
        col.separator()
        col.prop(settings, "auto_resolve")
        col.operator("mocap_autolabel.resolve", icon="FILE_REFRESH")
        col.separator()
        col.operator("mocap_autolabel.fill_gaps", icon="KEYTYPE_GENERATED_VEC")
        col.operator("mocap_autolabel.clear_fill", icon="X")
        col.operator("mocap_autolabel.export_labeled", icon="EXPORT")


class MOCAPAL_PT_legend(_Sidebar, bpy.types.Panel):
    bl_label = "Legend"
    bl_parent_id = "MOCAPAL_PT_review"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        from ..blender.review import FINGER_COLOR_SETS, legend

        layout = self.layout
        settings = context.scene.mocap_autolabel
        layout.label(text="Keyframe types (Dope Sheet, Timeline):")
        for key_type, meaning in legend():
            layout.label(text=meaning.capitalize(), icon=_KEY_ICONS[key_type])
        layout.label(text="Channel groups and viewport, by finger:")
        grid = layout.grid_flow(columns=3, even_columns=True)
        for finger, color_set in FINGER_COLOR_SETS.items():
            grid.label(text=finger.capitalize(), icon=_FINGER_ICONS[color_set])
        row = layout.row()
        row.prop(settings, "show_overlay")
        row.prop(settings, "show_sticks")
        layout.label(text="Dope Sheet: View > Show Group Colors", icon="INFO")


class MOCAPAL_UL_fill_preview(bpy.types.UIList):
    """The previewed marker's gaps: frames, the method that fills each (or why it stays open), its expected error."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        row = layout.row(align=True)
        row.label(text=f"{item.frame_start}-{item.frame_end}")
        if item.method:
            row.label(text=item.method if item.asked == "auto" else f"{item.method} (picked)",
                      icon="KEYTYPE_GENERATED_VEC")
            row.label(text=f"{item.error_mm:.1f} mm")
        else:
            row.label(text=f"open: {item.reason}", icon="ERROR")


class MOCAPAL_PT_cleanup(_Sidebar, bpy.types.Panel):
    """Spikes, smoothing, short fragments, quick labeling and a fill preview per gap, on the labeled markers."""

    bl_label = "Cleanup"
    bl_parent_id = "MOCAPAL_PT_review"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        from ..blender.takes import has_review, load_state

        settings = context.scene.mocap_autolabel
        cs = settings.cleanup
        layout = self.layout
        if not has_review(settings.take):
            layout.label(text="Label a take to clean it up", icon="INFO")
            return
        layout.label(text="The selected labeled markers (all if none is):")
        col = layout.column(align=True)
        row = col.row(align=True)
        row.prop(cs, "max_accel")
        row.prop(cs, "max_speed")
        col.operator("mocap_autolabel.find_spikes", icon="KEYTYPE_EXTREME_VEC")
        col = layout.column(align=True)
        row = col.row(align=True)
        row.prop(cs, "cutoff_hz")
        row.prop(cs, "order")
        col.operator("mocap_autolabel.smooth", icon="MOD_SMOOTH")
        col = layout.column(align=True)
        col.prop(cs, "min_frames")
        col.operator("mocap_autolabel.delete_short_fragments", icon="TRASH")
        names = load_state(settings.take).labeling.names
        col = layout.column(align=True)
        row = col.row(align=True)
        row.prop(cs, "quick_next")
        row.label(text=names[cs.quick_next] if cs.quick_next < len(names) else "(past the last label)")
        col.operator("mocap_autolabel.quick_label", icon="SORTALPHA")
        box = layout.box()
        row = box.row(align=True)
        row.prop(cs, "max_gap")
        row.operator("mocap_autolabel.fill_preview", icon="VIEWZOOM")
        if not cs.preview:
            return
        box.label(text=f"{cs.preview_name}: {len(cs.preview)} gaps")
        box.template_list("MOCAPAL_UL_fill_preview", "", cs, "preview", cs, "preview_index", rows=4)
        if 0 <= cs.preview_index < len(cs.preview):
            item = cs.preview[cs.preview_index]
            if item.donors:
                box.label(text=f"From {len(item.donors.split(', '))}: {item.donors}")
            if item.tried:
                box.label(text=f"Tried: {item.tried}")
        row = box.row(align=True)
        row.operator_menu_enum("mocap_autolabel.fill_preview_method", "method", text="Fill Gap With")
        row.operator("mocap_autolabel.fill_preview_apply", text="Apply", icon="CHECKMARK")


classes = (MOCAPAL_UL_uncertain, MOCAPAL_UL_corrections, MOCAPAL_UL_bone_map, MOCAPAL_PT_label, MOCAPAL_PT_retarget,
           MOCAPAL_PT_review, MOCAPAL_PT_relabel, MOCAPAL_PT_corrections, MOCAPAL_PT_legend, MOCAPAL_UL_fill_preview,
           MOCAPAL_PT_cleanup)
