// riderlive sample client for Unity: the rider and the horse as Transform hierarchies, live.
// Add this component to an empty GameObject and press Play with `riderlive serve` running.
// It reads the hello (bones, parents, bind pose), subscribes to binary frames with
// "pose" (per bone: tx ty tz qx qy qz qw, local, riderlive axes) and, every Update,
// applies the newest frame only (the receive loop drains the socket: no backlog).
// Axes: riderlive is right-handed (+x forward, +y up, +z right); Unity is left-handed
// (+x right, +y up, +z forward): position (x, y, z) -> (z, y, x), rotation -> (-z, -y, -x, w).
// For a humanoid avatar, use VMC instead (riderlive serve --vmc, EVMC4U): docs/vmc.md.
using System;
using System.Net.WebSockets;
using System.Text;
using System.Threading;
using System.Threading.Tasks;
using UnityEngine;

public class RiderliveSkeleton : MonoBehaviour
{
    public string url = "ws://127.0.0.1:8000/ws/rider";
    public float rate = 60f;

    [Serializable] class Bone { public string name; public int parent; public float[] offset; }
    [Serializable] class Rig { public Bone[] bones; }
    [Serializable] class Skeletons { public Rig rider; public Rig horse; }
    [Serializable] class Hello { public string type; public Skeletons skeletons; }

    readonly ClientWebSocket socket = new ClientWebSocket();
    readonly CancellationTokenSource stop = new CancellationTokenSource();
    byte[] latest;  // the newest binary frame; written by the receive loop, taken by Update
    Transform[] riderBones, horseBones;
    Hello hello;

    async void Start()
    {
        await socket.ConnectAsync(new Uri(url), stop.Token);
        hello = JsonUtility.FromJson<Hello>(Encoding.UTF8.GetString(await Receive()));
        riderBones = Build("rider", hello.skeletons.rider.bones);
        horseBones = Build("horse", hello.skeletons.horse.bones);
        string subscribe = "{\"type\":\"subscribe\",\"pose\":true,\"encoding\":\"binary\",\"channels\":[],\"rate\":"
            + rate.ToString(System.Globalization.CultureInfo.InvariantCulture) + "}";
        await socket.SendAsync(new ArraySegment<byte>(Encoding.UTF8.GetBytes(subscribe)),
            WebSocketMessageType.Text, true, stop.Token);
        _ = Task.Run(ReceiveLoop);
    }

    Transform[] Build(string name, Bone[] bones)
    {
        var root = new GameObject(name).transform;
        root.SetParent(transform, false);
        var made = new Transform[bones.Length];
        for (int i = 0; i < bones.Length; i++)
        {
            made[i] = GameObject.CreatePrimitive(PrimitiveType.Sphere).transform;
            made[i].name = bones[i].name;
            made[i].localScale = Vector3.one * 0.04f;
            made[i].SetParent(bones[i].parent < 0 ? root : made[bones[i].parent], false);
            float[] o = bones[i].offset;
            made[i].localPosition = new Vector3(o[2], o[1], o[0]);  // the bind pose: identity rotations
        }
        return made;
    }

    async Task<byte[]> Receive()
    {
        var buffer = new byte[1 << 16];
        var message = new System.IO.MemoryStream();
        WebSocketReceiveResult result;
        do
        {
            result = await socket.ReceiveAsync(new ArraySegment<byte>(buffer), stop.Token);
            message.Write(buffer, 0, result.Count);
        } while (!result.EndOfMessage);
        return message.ToArray();
    }

    async Task ReceiveLoop()
    {
        while (socket.State == WebSocketState.Open && !stop.IsCancellationRequested)
        {
            byte[] data = await Receive();
            if (data.Length > 40 && data[0] == (byte)'R' && data[1] == (byte)'L')
                Interlocked.Exchange(ref latest, data);  // keep only the newest frame
        }
    }

    void Update()
    {
        byte[] frame = Interlocked.Exchange(ref latest, null);
        if (frame == null || riderBones == null) return;
        int header = BitConverter.ToUInt16(frame, 4), flags = frame[7];
        int r = BitConverter.ToUInt16(frame, 32), k = BitConverter.ToUInt16(frame, 34);
        int extension = 40, offset = header + 8 * (r + ((flags & 1) != 0 ? k : 0));
        if ((flags & 2) != 0) { offset += 8 * BitConverter.ToUInt16(frame, extension); extension += 8; }
        if ((flags & 4) == 0) return;
        int riderFloats = BitConverter.ToUInt16(frame, extension), horseFloats = BitConverter.ToUInt16(frame, extension + 2);
        Apply(riderBones, frame, offset, riderFloats / 7);
        Apply(horseBones, frame, offset + 8 * riderFloats, horseFloats / 7);
    }

    static void Apply(Transform[] bones, byte[] frame, int offset, int count)
    {
        for (int i = 0; i < count && i < bones.Length; i++)
        {
            int at = offset + 56 * i;  // 7 doubles per bone
            bones[i].localPosition = new Vector3(F(frame, at, 2), F(frame, at, 1), F(frame, at, 0));
            bones[i].localRotation = new Quaternion(-F(frame, at, 5), -F(frame, at, 4), -F(frame, at, 3), F(frame, at, 6));
        }
    }

    static float F(byte[] frame, int at, int j) { return (float)BitConverter.ToDouble(frame, at + 8 * j); }

    void OnDestroy()
    {
        stop.Cancel();
        socket.Dispose();
    }
}
