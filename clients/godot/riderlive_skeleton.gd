# riderlive sample client for Godot 4: the rider and the horse as Skeleton3D nodes, live.
# Attach to a Node3D and run the scene with `riderlive serve` running. It reads the hello
# (bones, parents, bind pose), subscribes to binary frames with "pose" (per bone:
# tx ty tz qx qy qz qw, local, riderlive axes) and poses both skeletons from the newest
# frame each _process (it drains every waiting packet first: no backlog).
# Axes: riderlive is +x forward, +y up, +z right; Godot is right-handed, +x right, +y up,
# -z forward: position (x, y, z) -> (z, y, -x), rotation (x, y, z, w) -> (z, y, -x, w).
extends Node3D

@export var url := "ws://127.0.0.1:8000/ws/rider"
@export var rate := 60.0

var socket := WebSocketPeer.new()
var skeletons := {}  # "rider" / "horse" -> Skeleton3D
var subscribed := false


func _ready() -> void:
	var error := socket.connect_to_url(url)
	if error != OK:
		push_error("riderlive: cannot connect to %s (%s)" % [url, error])


func _process(_delta: float) -> void:
	socket.poll()
	if socket.get_ready_state() != WebSocketPeer.STATE_OPEN:
		return
	var newest := PackedByteArray()
	while socket.get_available_packet_count() > 0:
		var packet := socket.get_packet()
		if socket.was_string_packet():
			_on_text(packet.get_string_from_utf8())
		else:
			newest = packet  # keep only the newest frame
	if newest.size() > 40:
		_apply(newest)


func _on_text(text: String) -> void:
	var message = JSON.parse_string(text)
	if message == null or message.get("type") != "hello" or subscribed:
		return
	for name in ["rider", "horse"]:
		skeletons[name] = _build(name, message["skeletons"][name]["bones"])
	var request := {
		"type": "subscribe", "pose": true, "encoding": "binary", "channels": [], "rate": rate
	}
	socket.send_text(JSON.stringify(request))
	subscribed = true


func _build(skeleton_name: String, bones: Array) -> Skeleton3D:
	var skeleton := Skeleton3D.new()
	skeleton.name = skeleton_name
	add_child(skeleton)
	for bone in bones:
		var index := skeleton.add_bone(bone["name"])
		skeleton.set_bone_parent(index, int(bone["parent"]))
		var o: Array = bone["offset"]
		skeleton.set_bone_rest(index, Transform3D(Basis(), Vector3(o[2], o[1], -o[0])))
	skeleton.reset_bone_poses()
	return skeleton


func _apply(frame: PackedByteArray) -> void:
	var header := frame.decode_u16(4)
	var flags := frame[7]
	var values := frame.decode_u16(32)
	var horse_values := frame.decode_u16(34) if flags & 1 else 0
	var extension := 40
	var offset := header + 8 * (values + horse_values)
	if flags & 2:
		offset += 8 * frame.decode_u16(extension)
		extension += 8
	if not flags & 4:
		return
	var counts := [frame.decode_u16(extension), frame.decode_u16(extension + 2)]
	for k in 2:
		var skeleton: Skeleton3D = skeletons[["rider", "horse"][k]]
		for i in counts[k] / 7:
			var at: int = offset + 56 * i
			var p := Vector3(
				frame.decode_double(at + 16), frame.decode_double(at + 8), -frame.decode_double(at)
			)
			var q := Quaternion(
				frame.decode_double(at + 40), frame.decode_double(at + 32),
				-frame.decode_double(at + 24), frame.decode_double(at + 48)
			)
			skeleton.set_bone_pose_position(i, p)
			skeleton.set_bone_pose_rotation(i, q)
		offset += 8 * counts[k]
